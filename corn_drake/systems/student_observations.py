"""StudentObservations: what the student policy sees, one output per key.

cloud (512 x 3, flattened): the segmented partial cloud plus N(0, cloud_noise_std) noise per
coordinate (the authors' PerturbCloud); the noise comes in on ``unit_noise`` from a Drake
RandomSource, so it is seeded and resampled by the context like any other random input.
hand_state (9), robot_state (14), previous_action (20): as the teacher's.
goal (9): the goal relative to the tracker's *estimated* pose, not the true one.
"""

from __future__ import annotations

from pydrake.systems.framework import LeafSystem

from corn_drake.scene.franka import NUM_JOINTS
from corn_drake.systems.ik import ACTION_DIM

STUDENT_OBS_KEYS = ("cloud", "hand_state", "robot_state", "previous_action", "goal")


class StudentObservations(LeafSystem):
    def __init__(self, num_points: int, cloud_noise_std: float):
        super().__init__()
        self._std = float(cloud_noise_std)
        n3 = 3 * num_points
        self.DeclareVectorInputPort("points", n3)
        self.DeclareVectorInputPort("unit_noise", n3)
        self.DeclareVectorInputPort("hand_state", 9)
        self.DeclareVectorInputPort("robot_state", 2 * NUM_JOINTS)
        self.DeclareVectorInputPort("previous_action", ACTION_DIM)
        self.DeclareVectorInputPort("estimated_goal", 9)
        self.DeclareVectorOutputPort("cloud", n3, self._calc_cloud)
        for key, port, size in (("hand_state", "hand_state", 9),
                                ("robot_state", "robot_state", 2 * NUM_JOINTS),
                                ("previous_action", "previous_action", ACTION_DIM),
                                ("goal", "estimated_goal", 9)):
            self.DeclareVectorOutputPort(key, size, self._copier(port))

    def _copier(self, port_name):
        def calc(context, output):
            output.SetFromVector(self.GetInputPort(port_name).Eval(context))
        return calc

    def _calc_cloud(self, context, output):
        pts = self.GetInputPort("points").Eval(context)
        if self._std > 0:
            pts = pts + self._std * self.GetInputPort("unit_noise").Eval(context)
        output.SetFromVector(pts)
