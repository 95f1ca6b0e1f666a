"""Exact signed distance to the closed gripper (union of its collision boxes), in numpy.

Outside the gripper the distance to the union is the minimum over boxes, exactly; the sign is
exact everywhere (inside iff inside some box), which is all the labels need. Points are given in
the panda_tool frame; the boxes come from corn_drake.scene.gripper.gripper_boxes, the very
shapes the simulator collides with.
"""

from __future__ import annotations

import numpy as np
import torch

from corn_drake.scene.gripper import gripper_boxes


class GripperSDF:
    def __init__(self, boxes=None):
        boxes = boxes or gripper_boxes()
        self.R = np.stack([b.X_TB[:3, :3] for b in boxes])  # (K, 3, 3) box -> tool rotation
        self.t = np.stack([b.X_TB[:3, 3] for b in boxes])  # (K, 3)
        self.half = np.stack([b.half_extents for b in boxes])  # (K, 3)

    def _local(self, points: np.ndarray) -> np.ndarray:
        """(K, ..., 3) points in each box's frame."""
        t = self.t.reshape(-1, *([1] * (points.ndim - 1)), 3).astype(points.dtype)
        return np.einsum("k...j,kjl->k...l", points[None] - t, self.R.astype(points.dtype))

    def _box_excess(self, local: np.ndarray, R: np.ndarray, p: np.ndarray):
        """Per box, |box-frame point| - half extents (n, m, 3) for clouds local (n, m, 3)
        moved into the tool frame by R (n, 3, 3), p (n, 3).

        The hot loop of the contact-data generator: one batched affine map per box in torch
        float32 (BLAS baddbmm and fused elementwise kernels), 3x faster than numpy einsum here.
        """
        x = torch.from_numpy(np.ascontiguousarray(local, dtype=np.float32))
        for Rb, tb, hb in zip(self.R, self.t, self.half):
            # box-frame point = Rb^T (R x + p - tb) = A x + b
            A = torch.from_numpy((Rb.T[None] @ R).astype(np.float32))
            b = torch.from_numpy(((p - tb) @ Rb).astype(np.float32))
            yield torch.baddbmm(b.unsqueeze(1), x, A.transpose(1, 2)).abs_().sub_(
                torch.from_numpy(hb.astype(np.float32)))

    def nearest_in_batch(self, local: np.ndarray, R: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Index (n,) of the point nearest to the gripper in each cloud (see _box_excess)."""
        best = None
        for q in self._box_excess(local, R, p):
            d = q.clamp(min=0).norm(dim=-1).add_(q.amax(dim=-1).clamp_(max=0))
            best = d if best is None else torch.minimum(best, d)
        return best.argmin(dim=1).numpy()

    def inside_batch(self, local: np.ndarray, R: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Inside-or-on mask (n, m) for clouds given as in _box_excess."""
        inside = None
        for q in self._box_excess(local, R, p):
            box = q.amax(dim=-1) <= 0
            inside = box if inside is None else inside | box
        return inside.numpy()

    def signed_distance(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(distance (...), unit gradient (..., 3)) for tool-frame points (..., 3)."""
        local = self._local(points)
        half = self.half.reshape(-1, *([1] * (points.ndim - 1)), 3)
        q = np.abs(local) - half
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
        inside = np.minimum(q.max(axis=-1), 0.0)
        d = outside + inside  # (K, ...)
        k = d.argmin(axis=0)
        take = lambda a: np.take_along_axis(a, k[None, ..., None] if a.ndim == d.ndim + 1 else k[None], 0)[0]
        q_k, local_k, d_k = take(q), take(local), take(d)
        # Gradient in the box frame: towards the nearest face from inside, along max(q, 0) outside.
        g = np.where((d_k > 0)[..., None], np.maximum(q_k, 0.0), 0.0)
        axis = q_k.argmax(axis=-1)
        inner = np.zeros_like(q_k)
        np.put_along_axis(inner, axis[..., None], 1.0, axis=-1)
        g = np.where((d_k > 0)[..., None], g, inner) * np.where(local_k < 0, -1.0, 1.0)
        g = g / np.maximum(np.linalg.norm(g, axis=-1, keepdims=True), 1e-12)
        grad = np.einsum("...ij,...j->...i", self.R[k], g)  # box -> tool frame
        return d_k, grad

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Boolean (...) mask: inside (or on) any gripper box."""
        q = np.abs(self._local(points)) - self.half.reshape(-1, *([1] * (points.ndim - 1)), 3)
        return (q.max(axis=-1) <= 0.0).any(axis=0)
