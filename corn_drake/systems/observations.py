"""TeacherObservations: the privileged observation of the teacher policy.

Keys and shapes are the contract's (corn_drake/contract.py): cloud (the object's fixed surface
sample moved rigidly to its current pose), hand_state, robot_state, previous_action (physical
units), goal (goal position minus object position + 6D of R_goal R_obj^T), physics and
object_keypoints (the bounding-box corners at the current pose, the input of the `state`
baseline, which sees no cloud).

Everything is computed once per state into the cached `observation` output (ObservationLayout
packs and unpacks it); the named per-key outputs are slices of it for readers of one signal.
Readers of all of them (the gymnasium env, PolicySystem) take the packed port: one Python call
per policy step instead of seven.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector, LeafSystem

from corn_drake.contract import (ACTION_DIM, FREE_BODY_STATE_DIM, KEYPOINTS_DIM, OBS_KEYS,
                                 PHYSICS_DIM, POSE7_DIM, POSE7_POSITION, POSE7_QUATERNION,
                                 POSITION_DIM, ROBOT_STATE_DIM,
                                 free_body_pose, observation_shapes, slice_size)
from corn_drake.scene.franka import NUM_JOINTS, make_controller_plant, tool_frame
from corn_drake.transforms import pose9, quat_wxyz_to_matrix


class ObservationLayout:
    """Offsets of each key in the packed observation vector (keys in OBS_KEYS order)."""

    def __init__(self, num_points: int):
        self.shapes = observation_shapes(num_points)
        sizes = [int(np.prod(self.shapes[k])) for k in OBS_KEYS]
        ends = np.cumsum(sizes)
        self.slices = {k: slice(int(e - n), int(e)) for k, n, e in zip(OBS_KEYS, sizes, ends)}
        self.size = int(ends[-1])

    def unpack(self, packed: np.ndarray, dtype=np.float32) -> dict[str, np.ndarray]:
        return {k: np.asarray(packed[s], dtype).reshape(self.shapes[k]) for k, s in self.slices.items()}


class TeacherObservations(LeafSystem):
    def __init__(self, num_points: int, robot_base: np.ndarray):
        super().__init__()
        self.layout = ObservationLayout(num_points)
        self._plant = make_controller_plant()
        self._plant_context = self._plant.CreateDefaultContext()
        self._tool = tool_frame(self._plant)
        self._X_WB = RigidTransform(np.asarray(robot_base, float))
        self._in = {name: self.DeclareVectorInputPort(name, size) for name, size in (
            ("robot_state", ROBOT_STATE_DIM), ("object_state", FREE_BODY_STATE_DIM),
            ("previous_action", ACTION_DIM), ("goal_pose", POSE7_DIM), ("physics_params", PHYSICS_DIM),
            ("object_cloud", POSITION_DIM * num_points), ("object_corners", KEYPOINTS_DIM))}
        self._packed = self.DeclareVectorOutputPort("observation", self.layout.size, self._calc_packed)
        for key in OBS_KEYS:
            self.DeclareVectorOutputPort(key, slice_size(self.layout.slices[key]),
                                         self._slice_calculator(key))

    def tool_pose(self, q: np.ndarray) -> RigidTransform:
        self._plant.SetPositions(self._plant_context, q)
        return self._X_WB @ self._plant.CalcRelativeTransform(
            self._plant_context, self._plant.world_frame(), self._tool)

    def _calc_packed(self, context, output: BasicVector):
        def get(name):
            return self._in[name].Eval(context)

        x = get("robot_state")
        p, R = free_body_pose(get("object_state"))
        X_tool = self.tool_pose(x[:NUM_JOINTS])
        g = get("goal_pose")
        parts = {
            "cloud": get("object_cloud").reshape(-1, POSITION_DIM) @ R.T + p,
            "hand_state": pose9(X_tool.translation(), X_tool.rotation().matrix()),
            "robot_state": x,
            "previous_action": get("previous_action"),
            "goal": pose9(g[POSE7_POSITION] - p, quat_wxyz_to_matrix(g[POSE7_QUATERNION]) @ R.T),
            "physics": get("physics_params"),
            "object_keypoints": get("object_corners").reshape(-1, POSITION_DIM) @ R.T + p,
        }
        out = output.get_mutable_value()
        for key, s in self.layout.slices.items():
            out[s] = np.ravel(parts[key])

    def _slice_calculator(self, key: str):
        s = self.layout.slices[key]

        def calc(context, output: BasicVector):
            output.SetFromVector(self._packed.Eval(context)[s])

        return calc
