"""Small numpy pose helpers shared by systems, envs and datasets."""

from __future__ import annotations

import math

import numpy as np


def rot6d(R: np.ndarray) -> np.ndarray:
    """6D rotation: the first two columns of R, column after column (6,)."""
    return np.concatenate([R[:, 0], R[:, 1]])


def pose9(p: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Position + 6D rotation (9,): the hand-state / relative-goal encoding of the paper."""
    return np.concatenate([p, rot6d(R)])


def from_pose9(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(p, R) back from pose9's encoding (columns orthonormal, as pose9 writes them)."""
    x = np.asarray(x, float)
    return x[:3], np.column_stack([x[3:6], x[6:9], np.cross(x[3:6], x[6:9])])


def rotation_angle(R: np.ndarray) -> float:
    """Angle (rad) of a rotation matrix, robust near 0 and pi."""
    c = (float(R[0, 0]) + float(R[1, 1]) + float(R[2, 2]) - 1.0) / 2.0
    return math.acos(min(1.0, max(-1.0, c))) if c == c else math.nan


def quat_matrix_entries(w, x, y, z) -> tuple:
    """The 9 entries (row after row) of the rotation matrix of a unit quaternion (w, x, y, z).

    Plain arithmetic, so the same formula serves numpy arrays here and torch tensors in
    nn/geometry.py: each array library only stacks the entries its own way."""
    return (1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
            2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y))


def quat_wxyz_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) in Drake's w, x, y, z order;
    normalised first, so any nonzero scaling of a quaternion gives the same rotation."""
    q = np.asarray(q, float)
    if q.shape == (4,):
        # One quaternion (every policy step's systems convert several): Python floats, since
        # numpy's per-call overhead on 4 numbers cost 40 us a call against 3 us this way.
        w, x, y, z = q.tolist()
        n = math.sqrt(w * w + x * x + y * y + z * z)
        if n == 0.0:  # as the array path below: a zero quaternion gives NaN, not an error
            return np.full((3, 3), np.nan)
        return np.array(quat_matrix_entries(w / n, x / n, y / n, z / n)).reshape(3, 3)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    entries = quat_matrix_entries(q[..., 0], q[..., 1], q[..., 2], q[..., 3])
    return np.stack(entries, axis=-1).reshape(*q.shape[:-1], 3, 3)


def yaw_matrix(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def up_angle(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle (rad) between the world's up direction seen in two body orientations: 0 when the
    object rests on the same face in both (whatever the yaw), large when it tipped or rolled."""
    up = np.array([0.0, 0.0, 1.0])
    c = float((np.asarray(R_a).T @ up) @ (np.asarray(R_b).T @ up))
    return math.acos(min(1.0, max(-1.0, c)))
