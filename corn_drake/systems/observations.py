"""TeacherObservations: the privileged observation of the teacher policy, one output per key.

cloud (N x 3, flattened): the object's fixed surface sample moved rigidly to its current pose;
hand_state (9): tool position + 6D rotation, world frame; robot_state (14): [q, qdot];
previous_action (20, physical units); goal (9): goal position minus object position + 6D of
R_goal R_obj^T; physics (5): mass, table / object / finger friction, restitution;
object_keypoints (24): the 8 bounding-box corners at the current pose, world frame (the input
of the `state` baseline, which sees no cloud).
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector, LeafSystem

from corn_drake.scene.franka import NUM_JOINTS, make_controller_plant, tool_frame
from corn_drake.systems.ik import ACTION_DIM
from corn_drake.transforms import pose9, quat_wxyz_to_matrix

OBS_KEYS = ("cloud", "hand_state", "robot_state", "previous_action", "goal", "physics",
            "object_keypoints")


def object_pose_from_state(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position, rotation matrix) from a free body's 13-D state [q_wxyz, p, w, v]."""
    return x[4:7], quat_wxyz_to_matrix(x[:4])


class TeacherObservations(LeafSystem):
    def __init__(self, num_points: int, robot_base: np.ndarray):
        super().__init__()
        self._n = num_points
        self._plant = make_controller_plant()
        self._plant_context = self._plant.CreateDefaultContext()
        self._tool = tool_frame(self._plant)
        self._X_WB = RigidTransform(np.asarray(robot_base, float))
        self.DeclareVectorInputPort("robot_state", 2 * NUM_JOINTS)
        self.DeclareVectorInputPort("object_state", 13)
        self.DeclareVectorInputPort("previous_action", ACTION_DIM)
        self.DeclareVectorInputPort("goal_pose", 7)
        self.DeclareVectorInputPort("physics_params", 5)
        self.DeclareVectorInputPort("object_cloud", 3 * num_points)
        self.DeclareVectorInputPort("object_corners", 24)
        self.DeclareVectorOutputPort("cloud", 3 * num_points, self._calc_cloud)
        self.DeclareVectorOutputPort("hand_state", 9, self._calc_hand)
        self.DeclareVectorOutputPort("robot_state", 2 * NUM_JOINTS, self._calc_robot)
        self.DeclareVectorOutputPort("previous_action", ACTION_DIM, self._calc_prev)
        self.DeclareVectorOutputPort("goal", 9, self._calc_goal)
        self.DeclareVectorOutputPort("physics", 5, self._calc_physics)
        self.DeclareVectorOutputPort("object_keypoints", 24, self._calc_keypoints)

    def tool_pose(self, q: np.ndarray) -> RigidTransform:
        self._plant.SetPositions(self._plant_context, q)
        return self._X_WB @ self._plant.CalcRelativeTransform(
            self._plant_context, self._plant.world_frame(), self._tool)

    def _posed(self, context, port_index: int) -> np.ndarray:
        """Object-frame points from input `port_index`, moved to the object's current pose."""
        p, R = object_pose_from_state(self.get_input_port(1).Eval(context))
        return (self.get_input_port(port_index).Eval(context).reshape(-1, 3) @ R.T + p).reshape(-1)

    def _calc_cloud(self, context, output: BasicVector):
        output.SetFromVector(self._posed(context, 5))

    def _calc_keypoints(self, context, output: BasicVector):
        output.SetFromVector(self._posed(context, 6))

    def _calc_hand(self, context, output: BasicVector):
        X = self.tool_pose(self.get_input_port(0).Eval(context)[:NUM_JOINTS])
        output.SetFromVector(pose9(X.translation(), X.rotation().matrix()))

    def _calc_robot(self, context, output: BasicVector):
        output.SetFromVector(self.get_input_port(0).Eval(context))

    def _calc_prev(self, context, output: BasicVector):
        output.SetFromVector(self.get_input_port(2).Eval(context))

    def _calc_goal(self, context, output: BasicVector):
        p, R = object_pose_from_state(self.get_input_port(1).Eval(context))
        g = self.get_input_port(3).Eval(context)
        output.SetFromVector(pose9(g[:3] - p, quat_wxyz_to_matrix(g[3:]) @ R.T))

    def _calc_physics(self, context, output: BasicVector):
        output.SetFromVector(self.get_input_port(4).Eval(context))
