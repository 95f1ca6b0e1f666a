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


def matrix_from_rot6d(x: torch.Tensor) -> torch.Tensor:
    """(..., 6) -> rotation matrices (..., 3, 3) by Gram-Schmidt (Zhou et al. 2019): the first
    column is the first 3 entries normalised, the second the next 3 made orthogonal to it and
    normalised, the third their cross product. Inverse of rot6d on rotations."""
    a, b = x[..., :3], x[..., 3:]
    c0 = torch.nn.functional.normalize(a, dim=-1)
    c1 = torch.nn.functional.normalize(b - (c0 * b).sum(-1, keepdim=True) * c0, dim=-1)
    return torch.stack([c0, c1, torch.linalg.cross(c0, c1)], dim=-1)


def rotation_angle(R: torch.Tensor, R_ref: torch.Tensor) -> torch.Tensor:
    """Geodesic angle (...,) in radians between rotations R and R_ref (..., 3, 3)."""
    cos = ((R * R_ref).sum((-2, -1)) - 1) / 2  # trace(R_ref^T R) = sum of elementwise products
    return torch.arccos(cos.clamp(-1.0, 1.0))


def random_rotations(n: int, generator: torch.Generator) -> torch.Tensor:
    """n uniform rotations (n, 3, 3), from normalised Gaussian quaternions."""
    return quat_wxyz_to_matrix(torch.randn(n, 4, generator=generator))
