"""ROT: the CORN patch encoder pretrained to estimate the relative rotation between two randomly
rotated copies of one cloud (pure torch).

As the paper's appendix (after Chen et al., visual dexterity, without its classification terms):
both copies go through the encoder; their patch tokens (16 x 128 each, the hand token left out)
are concatenated, and an MLP 512-64-6 (LayerNorm + ELU between, as the policy heads) regresses a
6D rotation (Zhou et al.), turned into a matrix by Gram-Schmidt.

Target: R_b R_a^T, the rotation taking copy a's orientation to copy b's. Loss: the squared
Frobenius distance ||R_pred - R_target||^2 = 4 (1 - cos angle), smooth everywhere (the geodesic
angle's arccos has an infinite slope at 0 and pi); the metrics report the angle too.

The two copies are independent samples of the object's surface (pretext/clouds.py), each at its
own place in the workspace with its own noise: with the same points in the same order, FPS (which
starts at point 0) and kNN would pick corresponding patches in both copies, and the task would
reduce to aligning 16 matched patch centres instead of recognising the shape's orientation.
"""

from __future__ import annotations

import torch
from torch import nn

from corn_drake.nn.encoders.corn_encoder import CORNEncoder
from corn_drake.nn.geometry import matrix_from_rot6d
from corn_drake.nn.policy import mlp


def relative_rotation(R_a: torch.Tensor, R_b: torch.Tensor) -> torch.Tensor:
    """R_b R_a^T (..., 3, 3): copy a's orientation to copy b's."""
    return R_b @ R_a.transpose(-1, -2)


def frobenius_loss(R: torch.Tensor, R_target: torch.Tensor) -> torch.Tensor:
    """Mean squared Frobenius distance between rotation matrices."""
    return (R - R_target).square().sum((-2, -1)).mean()


def chordal_mean(R: torch.Tensor) -> torch.Tensor:
    """The rotation (3, 3) closest to a set of rotations (n, 3, 3) in the mean squared Frobenius
    distance: the mean matrix projected onto SO(3) (SVD, the last axis flipped if need be)."""
    U, _, Vh = torch.linalg.svd(R.mean(0))
    flip = torch.ones(3, dtype=R.dtype)
    flip[2] = torch.sign(torch.det(U @ Vh))
    return U @ torch.diag(flip) @ Vh


class RelativeRotationModel(nn.Module):
    def __init__(self, encoder: CORNEncoder | None = None):
        super().__init__()
        self.encoder = encoder or CORNEncoder(dropout=0.1)
        self.head = mlp([2 * self.encoder.num_patches * self.encoder.dim, 512, 64, 6],
                        final_activation=False)

    def forward(self, points_a, hand_a, points_b, hand_b) -> torch.Tensor:
        """Normalised copies (B, N, 3) with their hands (B, 9) -> predicted R_b R_a^T (B, 3, 3)."""
        B = points_a.shape[0]
        # One encoder pass over both copies (2B clouds).
        tokens = self.encoder(torch.cat([points_a, points_b]), torch.cat([hand_a, hand_b]))[:, 1:]
        pair = torch.cat([tokens[:B].flatten(1), tokens[B:].flatten(1)], dim=-1)
        return matrix_from_rot6d(self.head(pair))
