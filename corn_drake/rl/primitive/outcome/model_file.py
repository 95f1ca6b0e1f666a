"""The outcome model file (a run folder's outcome_model.pt, rl/outcome_model.MODEL_FILE): the
outcome model, optionally further members fitted to the same data (an ensemble) and a tilt
classifier (rl/primitive/outcome/tilt_classifier.py), with what they take as input and the facts of their data.
Written by docs/results/primitive/outcome_model.py fit (rl/outcome_run.write_outcome_run), read
by rl/primitive_agent.load_primitive_run for a run whose chooser is "outcome_model".
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from corn_drake.rl.primitive.outcome.model import INPUT_KINDS, OutcomeModel
from corn_drake.rl.primitive.outcome.tilt_classifier import TiltClassifier


def save_outcome_model(path, model: OutcomeModel, tokens: bool, members=(), tilt=None,
                       **facts) -> None:
    """Writes the model (atomically) with what it takes as input and `facts` (its data); with
    `members`, further models fitted to the same data (an ensemble the chooser can be
    pessimistic with), with `tilt`, a rl/tilt_classifier.TiltClassifier."""
    from corn_drake.storage.checkpoint_files import save_checkpoint

    extra = {"members": [m.state_dict() for m in members]}
    if tilt is not None:
        extra.update(tilt=tilt.state_dict(), tilt_inputs=int(tilt.mean.shape[0]))
    save_checkpoint(path, {"model": model.state_dict(), "inputs": int(model.net[0].in_features),
                           "tokens": bool(tokens), **extra, **facts}, keep_previous=False)


@dataclasses.dataclass
class OutcomeParts:
    """What an outcome model file holds: its models (one, or an ensemble), the tilt classifier
    when it has one, and its other entries (tokens, data, updates...)."""
    models: list
    tilt: object
    facts: dict


def load_outcome_parts(path) -> OutcomeParts:
    """The file's models in eval mode, its tilt classifier (None if it has none) and its other
    entries, or MissingInputError / InputError naming the file."""
    from corn_drake.errors import InputError, MissingInputError
    from corn_drake.storage.checkpoint_files import load_checkpoint

    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"{path}: no outcome model (written by docs/results/primitive/"
                                f"outcome_model.py fit)")
    saved = load_checkpoint(path, required=("model", "inputs", "tokens"), fallback=False)
    if saved is None:
        raise InputError(f"{path}: not an outcome model file")

    def loaded(network, state, what):
        try:
            network.load_state_dict(state)
        except RuntimeError as error:
            raise InputError(f"{path}: the {what}'s weights do not fit its network "
                             f"({str(error).splitlines()[0]})") from None
        return network.eval()

    # Files written before ensembles hold one model and no "members".
    models = [loaded(OutcomeModel(int(saved["inputs"])), state, "outcome model")
              for state in [saved["model"], *saved.get("members", [])]]
    tilt = None
    if "tilt" in saved:
        tilt = loaded(TiltClassifier(int(saved["tilt_inputs"])), saved["tilt"],
                      "tilt classifier")
    facts = {k: v for k, v in saved.items() if k not in ("model", "members", "tilt")}
    facts["members"] = len(models)
    facts.setdefault("input_kind", "raw")  # files from before input kinds were recorded
    if facts["input_kind"] not in INPUT_KINDS:
        raise InputError(f"{path}: input_kind must be one of {', '.join(INPUT_KINDS)}, got "
                         f"{facts['input_kind']!r}")
    return OutcomeParts(models, tilt, facts)

