"""Torch pose helpers for the networks: quaternions -> 6D rotations, yaw rotations."""

from __future__ import annotations

import torch

from corn_drake.transforms import quat_matrix_entries


def quat_wxyz_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4), w first; normalised first.
    The formula is transforms.quat_matrix_entries, shared with the numpy version."""
    q = q / q.norm(dim=-1, keepdim=True)
    return torch.stack(quat_matrix_entries(*q.unbind(-1)), -1).reshape(*q.shape[:-1], 3, 3)


def rot6d(R: torch.Tensor) -> torch.Tensor:
    """First two columns of R, column after column (..., 6) — the numpy transforms.rot6d order."""
    return torch.cat([R[..., :, 0], R[..., :, 1]], dim=-1)


def yaw_matrix(yaw: torch.Tensor) -> torch.Tensor:
    c, s = torch.cos(yaw), torch.sin(yaw)
    zero, one = torch.zeros_like(yaw), torch.ones_like(yaw)
    return torch.stack([c, -s, zero, s, c, zero, zero, zero, one], -1).reshape(*yaw.shape, 3, 3)
