"""Which candidate primitives will tip or roll the object: a classifier the outcome chooser can
veto them with (rl/primitive/outcome/chooser.py, config `outcome.tilt_veto`).

Why (docs/results/primitive/README.md, items 37-38): tipping and rolling hold most of the
primitives' outcome variation, a model of the outcome learns them for the objects it saw and
not for others, and on push_turn a tipped object is a failed episode (the goal keeps its face).
Among held-out objects' lookahead states, choosing by the outcome model among the candidates
that did not tip (the simulator's own verdict) earned ~0.09 per primitive where the model alone
earned ~0.01. This classifier is the learned stand-in for that verdict.

Its inputs are object-relative, so that what it learns of a box's proportions carries to other
objects: rl/outcome_model.box_contact_features (an outcome model can take them too).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from corn_drake.rl.primitive.outcome.model import BATCH_ROWS, Candidates, box_contact_features
from corn_drake.transforms import quat_wxyz_to_matrix

TILT_DEG = 20.0  # the up direction turned further than this: the object tipped or rolled
HIDDEN = 128


def up_turn_deg(before_wxyz: np.ndarray, after_wxyz: np.ndarray) -> np.ndarray:
    """(R,) degrees between the world's vertical seen in the object's frame before and after
    (orientations as wxyz quaternions, (R, 4) each)."""
    up = np.stack([quat_wxyz_to_matrix(q)[2] for q in before_wxyz])  # R^T e_z: R's third row
    up_after = np.stack([quat_wxyz_to_matrix(q)[2] for q in after_wxyz])
    cos = np.einsum("ri,ri->r", up, up_after)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


class TiltClassifier(nn.Module):
    """Features -> the logit of "this primitive tips or rolls the object". The features are
    standardised by the fitted rows' mean and deviation, kept as buffers so the saved file
    carries them."""

    def __init__(self, inputs: int, hidden: int = HIDDEN):
        super().__init__()
        self.register_buffer("mean", torch.zeros(inputs))
        self.register_buffer("deviation", torch.ones(inputs))
        self.net = nn.Sequential(nn.Linear(inputs, hidden), nn.ReLU(), nn.Linear(hidden, hidden),
                                 nn.ReLU(), nn.Linear(hidden, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net((x - self.mean) / self.deviation)[:, 0]

    def probability(self, c: Candidates) -> np.ndarray:
        """(R,) the probability that each candidate tips or rolls the object."""
        with torch.no_grad():
            return torch.sigmoid(self(box_contact_features(c))).numpy()


def fit_tilt_classifier(x: torch.Tensor, tilted: np.ndarray, updates: int,
                        seed: int) -> TiltClassifier:
    """A classifier fitted to labels `tilted` (R,) from features `x` (R, F): logistic loss,
    `updates` Adam steps of BATCH_ROWS random rows; in eval mode."""
    if len(x) != len(tilted) or not len(x):
        raise ValueError(f"tilt classifier: {len(x)} feature rows for {len(tilted)} labels")
    torch.manual_seed(seed)
    classifier = TiltClassifier(x.shape[1])
    classifier.mean.copy_(x.mean(0))
    classifier.deviation.copy_(x.std(0) + 1e-6)
    optimiser = torch.optim.Adam(classifier.parameters(), lr=1e-3)
    y = torch.as_tensor(tilted, dtype=torch.float32)
    for _ in range(updates):
        batch = torch.randint(len(x), (BATCH_ROWS,))
        loss = nn.functional.binary_cross_entropy_with_logits(classifier(x[batch]), y[batch])
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    return classifier.eval()


def data_tilted(data: dict) -> np.ndarray:
    """(rows,) whether each collected candidate (lookahead_distill.collect's data with
    outcomes) tipped or rolled the object: its up direction turned past TILT_DEG."""
    return up_turn_deg(data["outcome_pose"][data["state"], 3:],
                       data["pose_after"][:, 3:]) > TILT_DEG
