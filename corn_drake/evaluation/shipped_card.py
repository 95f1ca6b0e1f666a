"""What a shipped weights folder's card.json says about its object library, and the checks
`evaluate` makes with it.

`ship` records on the card the content hash (assets/content_hash.py) of the library at the
library command's --out (`library_content_hash`) and each object's (`library_object_hashes`), so
that `evaluate --run <shipped folder>` can say when the library it is given is not the one the
card's numbers were measured on (another seed, an older version of the builder): the episodes
then differ from the card's report, and the user should know why before comparing numbers.

Lives in evaluation/ (not at the package root, which holds only the modules every floor shares)
because `evaluate` is what reads it; `ship` (a command, above) writes the fields.
"""

from __future__ import annotations

import sys
from pathlib import Path

from corn_drake.storage.weights_card import CARD

HASH_KEY = "library_content_hash"
OBJECTS_KEY = "library_object_hashes"


def library_card_fields(library: str | Path) -> dict:
    """The card keys that record `library`'s content: its hash and each object's."""
    from corn_drake.assets.content_hash import combined_hash, object_hashes

    hashes = object_hashes(library)
    return {HASH_KEY: combined_hash(hashes), OBJECTS_KEY: hashes}


def _card(run: str | Path) -> dict | None:
    """The card of a shipped weights folder, its fields' types checked (storage/weights_card.py),
    None for anything else (a run folder, a reference controller's name)."""
    from corn_drake.storage.weights_card import read_card

    return read_card(run)


def require_library(run: str | Path, library: str | Path, given: bool) -> None:
    """Before `evaluate --run <shipped folder>` reads `library`: a missing library that came from
    the shipped folder (`given` False: no --objects) is a MissingInputError naming the card and
    its library_command, which builds it. A missing --objects folder is left to the usual error,
    which names it."""
    from corn_drake.assets.manifest import manifest_path
    from corn_drake.errors import MissingInputError

    card = _card(run)
    if card is None or given or manifest_path(library).is_file():
        return
    raise MissingInputError(
        f"object library {library}: no manifest.json; the path comes from {Path(run) / CARD}, "
        f"whose library_command builds it: {card.get('library_command')}")


def warn_if_other_library(run: str | Path, library: str | Path, ids: list[str],
                          stream=None) -> None:
    """One warning line on `stream` (stderr) when the objects `ids` of `library` differ from the
    same objects of the shipped folder's card's library. Objects the card's library does not
    hold are not compared; a library holding none of them is another library."""
    card = _card(run)
    recorded = (card or {}).get(OBJECTS_KEY)
    if not recorded:
        return  # not a shipped folder, or a card shipped before cards recorded their library
    from corn_drake.assets.content_hash import object_hashes

    shared = sorted(set(ids) & set(recorded))
    differ = [i for i, h in object_hashes(library, shared).items() if h != recorded[i]]
    if shared and not differ:
        return
    what = (f"{len(differ)} of the {len(shared)} evaluated objects it shares with the card's "
            f"library differ ({', '.join(differ[:3])}{'...' if len(differ) > 3 else ''})"
            if shared else "none of the evaluated objects is one of the card's library")
    print(f"warning: object library {library} is not the one {Path(run) / CARD} was measured "
          f"on: {what}; episodes will not match the card's report (its library: "
          f"{card.get('library_command')})", file=stream or sys.stderr)
