"""The policy's cross-attention as scores over the object's patches (pure torch).

The teacher head (nn/policy.CrossAttentionActorCritic) has 16 queries and a single head; each
query's weights are a softmax over the encoder's 17 tokens, so each query spends 1 and the 16
queries together spend 16. Token 0 is the hand token (nn/encoder.CORNEncoder puts it first);
tokens 1..16 are the patches in the order of their FPS centres.

Per patch, as in the paper's attention figure: the weight each patch gets, summed over the
queries. The hand token has no points on the object, so it is not painted: its share (the mean
over queries of its weight, in [0, 1]) is reported on its own, and the patch scores are divided
by what the patches got together, so they sum to 1 (a distribution over patches) whatever the
queries gave the hand. Then colours mean the same thing from one policy step to the next.

Painting per point: each point of the cloud takes the score of the patch whose centre is
nearest. The kNN groups overlap and need not cover the cloud, so "the patch a point belongs to"
is taken as its nearest centre: every point gets exactly one patch.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from corn_drake.nn.encoders.patchify import gather_points

HAND_TOKEN = 0  # CORNEncoder's token order: the hand token first, then the patches


@dataclasses.dataclass
class PatchAttention:
    """Attention of one policy step (or a batch: a leading batch axis on every field)."""

    patch_scores: np.ndarray  # (..., G) >= 0, summing to 1 over the patches
    hand_share: np.ndarray  # (...,) the queries' mean weight on the hand token, in [0, 1]
    point_patch: np.ndarray  # (..., N) int: the patch (0..G-1) each cloud point is painted with

    def point_scores(self) -> np.ndarray:
        """(..., N): each point's patch score."""
        return np.take_along_axis(self.patch_scores, self.point_patch, axis=-1)

    def select(self, i: int) -> "PatchAttention":
        """Entry `i` of a batch."""
        return PatchAttention(self.patch_scores[i], self.hand_share[i], self.point_patch[i])


def patch_scores(weights: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Cross-attention weights (B, Q, 1 + G) -> (patch scores (B, G) summing to 1, hand share
    (B,))."""
    if weights.ndim != 3 or weights.shape[-1] < 2:
        raise ValueError(f"weights must be (B, queries, 1 + patches), got {tuple(weights.shape)}")
    hand = weights[..., HAND_TOKEN].mean(dim=-1)
    per_patch = weights[..., HAND_TOKEN + 1:].sum(dim=1)
    return per_patch / per_patch.sum(dim=-1, keepdim=True), hand


def nearest_patch(points: torch.Tensor, center_idx: torch.Tensor) -> torch.Tensor:
    """(B, N) index of the nearest patch centre of each point; points (B, N, 3), center_idx
    (B, G) from patchify.patch_indices on the same points."""
    return torch.cdist(points, gather_points(points, center_idx)).argmin(dim=-1)
