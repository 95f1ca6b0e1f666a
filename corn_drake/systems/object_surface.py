"""ObjectSurface: the object's position and its cloud's outward surface normals in the world.

The teacher's observation carries the cloud's points (world frame) but not their normals; a
contact primitive needs both (it approaches a point along its normal). The normals of the
diagram's cloud subset are fixed in the object frame (the library's surface samples carry
them; a uniform size scale leaves them unchanged), so this system only rotates them by the
object's current orientation. Input `object_state` (the plant's free-body state); outputs
`normals` (N x 3, flattened) and `position` (3: the object frame's origin, which the goal's
relative pose turns about).
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from corn_drake.contract import FREE_BODY_STATE_DIM, POSITION_DIM, free_body_pose


class ObjectSurface(LeafSystem):
    def __init__(self, body_normals: np.ndarray):
        super().__init__()
        normals = np.asarray(body_normals, float)
        if normals.ndim != 2 or normals.shape[1] != POSITION_DIM or not np.isfinite(normals).all():
            raise ValueError(f"body_normals must be finite (N, 3), got {normals.shape}")
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        self._normals = normals / np.where(length > 1e-12, length, 1.0)
        self._state = self.DeclareVectorInputPort("object_state", FREE_BODY_STATE_DIM)
        self.DeclareVectorOutputPort("normals", normals.size, self._calc_normals)
        self.DeclareVectorOutputPort("position", POSITION_DIM, self._calc_position)

    def _calc_normals(self, context, output: BasicVector):
        _, R = free_body_pose(self._state.Eval(context))
        output.SetFromVector((self._normals @ R.T).reshape(-1))

    def _calc_position(self, context, output: BasicVector):
        p, _ = free_body_pose(self._state.Eval(context))
        output.SetFromVector(p)
