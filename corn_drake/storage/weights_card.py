"""A shipped weights folder's card.json, read with its fields' types checked.

What reads a card acts on a few of its fields (`evaluate` compares `library_object_hashes` with
the library it is given, `ship --out` reads `source_run` to know whose weights a folder holds).
A field of the wrong type (a hand edit, a damaged file) would otherwise pass through those checks
as a wrong conclusion (a string of hashes read as "none of the objects is the card's", a list
where a mapping belongs), so every field a card may hold is checked against its type here and a
wrong one is named in one line. Fields this version does not know are left alone (a newer
card).
"""

from __future__ import annotations

import json
from pathlib import Path

from corn_drake.errors import InputError

CARD = "card.json"
_NUMBER = (int, float)
_NONE = type(None)
# The fields `ship` writes (evaluation/shipping.py), by the type each must have.
FIELD_TYPES: dict[str, tuple[type, ...]] = {
    **{k: (str,) for k in ("policy", "task", "split", "report", "library_command",
                           "evaluate_command", "train_command", "source_run", "actions",
                           "env_steps_unit", "training_history", "library_content_hash",
                           "chooser", "teacher", "trained_perception", "cameras", "perception",
                           "init_from")},
    **{k: (int,) for k in ("env_steps", "episodes", "library_seed", "location_count")},
    **{k: _NUMBER for k in ("success_rate", "balanced_success_rate")},
    "successes_ending_at_rest": (int, _NONE),
    "success_rate_ending_at_rest": (*_NUMBER, _NONE),
    "complete": (bool,),
    "encoder": (dict, _NONE),
    **{k: (dict,) for k in ("outcome_model", "library_object_hashes", "bytes")},
    # Written by hand after a rebuild from the card's own commands (issue 62): its report, its
    # success and the core-hours each step took (tests/test_cards_are_recipes.py checks it).
    "rebuild": (dict,),
}
# Mappings whose values must be of one type: object id -> content hash, file -> size.
VALUE_TYPES = {"library_object_hashes": (str,), "bytes": (int,)}
_NAMES = {str: "a string", int: "an integer", float: "a number", bool: "true or false",
          dict: "an object", list: "a list", _NONE: "null"}


def _named(types: tuple[type, ...]) -> str:
    return " or ".join(dict.fromkeys(_NAMES.get(t, t.__name__) for t in types))


def _is(value, types: tuple[type, ...]) -> bool:
    # JSON's true/false are Python bools, which are ints too: a count is never a bool.
    if isinstance(value, bool) and bool not in types:
        return False
    return isinstance(value, types)


def read_card(folder: str | Path) -> dict | None:
    """The card of weights folder `folder` (None where it has none), or an InputError naming the
    file and the first field whose type is wrong."""
    path = Path(folder) / CARD
    if not path.is_file():
        return None
    try:
        card = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(f"{path}: not a JSON weights card ({e})") from None
    if not isinstance(card, dict):
        raise InputError(f"{path}: a weights card is a JSON object, got {_named((type(card),))}")
    for field, value in card.items():
        types = FIELD_TYPES.get(field)
        if types is not None and not _is(value, types):
            raise InputError(f"{path}: field {field!r} should be {_named(types)}, got "
                             f"{_named((type(value),))} ({json.dumps(value)[:40]}); the card is "
                             "damaged: ship the run again")
        inner = VALUE_TYPES.get(field)
        bad = [k for k, v in (value.items() if inner else ()) if not _is(v, inner)]
        if bad:
            raise InputError(f"{path}: field {field!r} maps {bad[0]!r} to "
                             f"{_named((type(value[bad[0]]),))}, not {_named(inner)}; the card "
                             "is damaged: ship the run again")
    return card
