"""The paper's `pn` baseline: a 3-layer PointNet pretrained on point-wise contact (pure torch).

Each point, concatenated with the gripper pose (9) as in the paper and with its own position in
the gripper's frame (3), goes through a shared MLP 15 -> 64 -> 128 -> 1024 (Linear-LN-ReLU on
channels-last tensors, faster than Conv1d on CPU); max-pooling gives the global feature the `pn`
policy uses. The contact head classifies every point from [its 64-D feature, the global
feature]. Big batches run in chunks to bound memory.

Why the gripper-frame channel: a point's contact label is "inside one of the gripper's boxes",
a function of R^T (p - t) alone. From [p, hand pose] only, the network must build those
products of pose and point out of sums and ReLUs, and at batch 64 it had not (held-out patch
AUROC 0.75, F1 0 after 1,500 steps; the paper pretrains a PyG U-Net we cannot afford on one
CPU core). R^T (p - t) costs one 3x3 product per point and is the kind of hand information
the paper gives the network (its pose, per point), in the frame where contact is decided.
"""

from __future__ import annotations

import torch
from torch import nn

from corn_drake.contract import HAND_STATE_DIM, POSE9_POSITION, POSE9_ROTATION
from corn_drake.nn.geometry import matrix_from_rot6d


# Gripper-frame coordinates are fed in decimetres: inputs are normalised by the contract's
# ENCODER_INPUT_SCALE (0.4 m), and x4 puts the gripper's boxes (2-20 cm) at a scale where the
# first layer's initial weights already separate them (a per-point MLP on these coordinates
# alone, batch 64: held-out point F1 0.81 after 500 steps at x4, 0.72 at x1).
GRIPPER_FRAME_GAIN = 4.0


class PointNetEncoder(nn.Module):
    def __init__(self, hand_dim: int = HAND_STATE_DIM, widths=(64, 128, 1024), chunk: int = 256):
        super().__init__()
        sizes = [3 + hand_dim + 3, *widths]
        self.layers = nn.ModuleList(
            nn.Sequential(nn.Linear(a, b), nn.LayerNorm(b), nn.ReLU()) for a, b in zip(sizes, sizes[1:]))
        self.feature_dim, self.chunk = widths[-1], chunk

    def point_features(self, points: torch.Tensor, hand: torch.Tensor):
        """(first-layer per-point features (B, N, 64), global feature (B, F)).
        points (B, N, 3) and hand (B, 9: position + 6D rotation) are normalised inputs."""
        R = matrix_from_rot6d(hand[:, POSE9_ROTATION])
        in_gripper = (points - hand[:, None, POSE9_POSITION]) @ R * GRIPPER_FRAME_GAIN  # R^T (p - t)
        x = torch.cat([points, hand.unsqueeze(1).expand(-1, points.shape[1], -1), in_gripper], dim=-1)
        x = first = self.layers[0](x)
        for layer in self.layers[1:]:
            x = layer(x)
        return first, x.max(dim=1).values

    def forward(self, points: torch.Tensor, hand: torch.Tensor) -> torch.Tensor:
        """Global feature (B, F), computed `chunk` clouds at a time."""
        return torch.cat([self.point_features(p, h)[1]
                          for p, h in zip(points.split(self.chunk), hand.split(self.chunk))])


class PointNetContactModel(nn.Module):
    def __init__(self, encoder: PointNetEncoder | None = None):
        super().__init__()
        self.encoder = encoder or PointNetEncoder()
        first = self.encoder.layers[0][0].out_features
        self.head = nn.Sequential(nn.Linear(first + self.encoder.feature_dim, 128), nn.ReLU(),
                                  nn.Linear(128, 1))

    def forward(self, points: torch.Tensor, hand: torch.Tensor) -> torch.Tensor:
        """Per-point contact logits (B, N).

        The head's first Linear reads [point feature (64), global feature (1024)]. Its
        global-feature half is the same for every point of a cloud, so it is applied once per
        cloud and broadcast: the same function as concatenating and applying it to all N
        points, at about half the step's FLOPs (the 1024-wide half dominated the head)."""
        first, pooled = self.encoder.point_features(points, hand)
        linear = self.head[0]
        k = first.shape[-1]
        per_point = first @ linear.weight[:, :k].T + linear.bias
        per_cloud = pooled @ linear.weight[:, k:].T
        x = per_point + per_cloud.unsqueeze(1)
        for layer in self.head[1:]:
            x = layer(x)
        return x.squeeze(-1)
