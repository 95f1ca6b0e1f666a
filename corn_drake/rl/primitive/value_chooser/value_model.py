"""The learned chooser's network and its file (a run folder's chooser_value.pt).

ValueNet maps a candidate's features (features.candidate_features) to two numbers: the reward
its primitive earns (the expert's one-step label, known for every candidate) and its two-step
value (r1 + 0.9 max r2, known where the expert's beam valued it). It chooses as the expert
does: the `beam` candidates of most predicted reward, then the one of most predicted value among
them (choose_index), so the value head is only asked where it was taught.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from corn_drake.rl.primitive.value_chooser.features import PRIOR_COLUMN

MODEL_FILE = "chooser_value.pt"


class ValueNet(nn.Module):
    """Features -> (reward, value); the inputs standardised by the training data's mean and
    spread, kept with the weights."""

    def __init__(self, inputs: int, hidden: int = 256):
        super().__init__()
        self.register_buffer("mean", torch.zeros(inputs))
        self.register_buffer("spread", torch.ones(inputs))
        self.net = nn.Sequential(nn.Linear(inputs, hidden), nn.LayerNorm(hidden), nn.ReLU(),
                                 nn.Linear(hidden, hidden), nn.LayerNorm(hidden), nn.ReLU(),
                                 nn.Linear(hidden, 2))
        nn.init.zeros_(self.net[-1].weight)  # starts as the prior alone
        nn.init.zeros_(self.net[-1].bias)

    def standardise_by(self, x: torch.Tensor) -> None:
        self.mean.copy_(x.mean(0))
        self.spread.copy_(x.std(0).clamp_min(1e-3))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(R, 2): predicted reward, predicted value: the outcome model's predicted reward
        (features.PRIOR_COLUMN) plus what the network learned to add to it, so an untrained
        network chooses as the proposing run's outcome model does and the labels correct it."""
        return self.net((x - self.mean) / self.spread) + x[:, PRIOR_COLUMN, None]


def choose_index(reward: np.ndarray, value: np.ndarray, beam: int) -> int:
    """The expert's rule on predictions: among the `beam` candidates of most reward (the first
    on ties), the one of most value (the first on ties)."""
    top = np.argsort(-np.asarray(reward), kind="stable")[:beam]
    return int(top[int(np.argmax(np.asarray(value)[top]))])


def save_value_model(path: Path, model: ValueNet, **facts) -> None:
    from corn_drake.storage.checkpoint_files import save_checkpoint

    save_checkpoint(path, {"model": model.state_dict(),
                           "inputs": int(model.net[0].in_features), **facts},
                    keep_previous=False)


def load_value_model(path: Path) -> tuple[ValueNet, dict]:
    """(the network in eval mode, the file's other entries), or an error naming the file."""
    from corn_drake.errors import InputError, MissingInputError
    from corn_drake.storage.checkpoint_files import load_checkpoint

    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"{path}: no chooser value model (written by `corn-drake "
                                "fit-chooser`)")
    saved = load_checkpoint(path, required=("model", "inputs", "tokens", "beam"),
                            fallback=False)
    if saved is None:
        raise InputError(f"{path}: not a chooser value model file")
    model = ValueNet(int(saved["inputs"]))
    try:
        model.load_state_dict(saved["model"])
    except RuntimeError as error:
        raise InputError(f"{path}: the weights do not fit the network "
                         f"({str(error).splitlines()[0]})") from None
    return model.eval(), {k: v for k, v in saved.items() if k != "model"}
