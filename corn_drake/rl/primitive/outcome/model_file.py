"""The outcome model file (a run folder's outcome_model.pt, rl/primitive/outcome/model.MODEL_FILE): the
outcome model, with what it takes as input and the facts of its data.
Written by `corn-drake fit-outcome` (rl/primitive/outcome/run_folder.write_outcome_run), read
by rl/primitive/agent.load_primitive_run for a run whose chooser is "outcome_model".
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from corn_drake.rl.primitive.outcome.model import INPUT_KINDS, OutcomeModel

# What files written before issue 52 may also hold: further ensemble members and a tilt
# classifier (with the reward its data measured for tilts), for the retired outcome.pessimism,
# tilt_veto and tilt_blend (config/retired.py). Reading leaves them out: the model is the same.
RETIRED_PARTS = ("members", "tilt", "tilt_inputs", "tilted_reward")


def save_outcome_model(path, model: OutcomeModel, tokens: bool, **facts) -> None:
    """Writes the model (atomically) with what it takes as input and `facts` (its data)."""
    from corn_drake.storage.checkpoint_files import save_checkpoint

    save_checkpoint(path, {"model": model.state_dict(), "inputs": int(model.net[0].in_features),
                           "tokens": bool(tokens), **facts}, keep_previous=False)


@dataclasses.dataclass
class OutcomeParts:
    """What an outcome model file holds: its model and its other entries (tokens, data,
    updates...)."""
    model: OutcomeModel
    facts: dict


def load_outcome_parts(path) -> OutcomeParts:
    """The file's model in eval mode and its other entries, or MissingInputError / InputError
    naming the file."""
    from corn_drake.errors import InputError, MissingInputError
    from corn_drake.storage.checkpoint_files import load_checkpoint

    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"{path}: no outcome model (written by `corn-drake "
                                "fit-outcome`)")
    saved = load_checkpoint(path, required=("model", "inputs", "tokens"), fallback=False)
    if saved is None:
        raise InputError(f"{path}: not an outcome model file")

    model = OutcomeModel(int(saved["inputs"]))
    try:
        model.load_state_dict(saved["model"])
    except RuntimeError as error:
        raise InputError(f"{path}: the outcome model's weights do not fit its network "
                         f"({str(error).splitlines()[0]})") from None
    facts = {k: v for k, v in saved.items() if k != "model" and k not in RETIRED_PARTS}
    facts.setdefault("input_kind", "raw")  # files from before input kinds were recorded
    if facts["input_kind"] not in INPUT_KINDS:
        raise InputError(f"{path}: input_kind must be one of {', '.join(INPUT_KINDS)}, got "
                         f"{facts['input_kind']!r}")
    return OutcomeParts(model.eval(), facts)

