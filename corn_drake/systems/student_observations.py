"""StudentObservations: what the student policy sees, one output per key.

cloud (512 x 3, flattened): the segmented partial cloud plus N(0, cloud_noise_std) noise per
coordinate (the authors' PerturbCloud). goal (9): the goal relative to the tracker's *estimated*
pose, not the true one, with N(0, goal_noise_std) noise on its position (first 3 entries).
Both stds are in metres (StudentObservationConfig converts the paper's normalised-unit
numbers). The unit noise comes in on ``cloud_unit_noise`` / ``goal_unit_noise`` from Drake
RandomSources, seeded through the context like any other random input
(diagrams.reseed_random_sources draws fresh seeds per episode).
hand_state (9), robot_state (14), previous_action (20): as the teacher's.
"""

from __future__ import annotations

from pydrake.systems.framework import LeafSystem

from corn_drake.errors import InputError
from corn_drake.scene.franka import NUM_JOINTS
from corn_drake.systems.ik import ACTION_DIM

STUDENT_OBS_KEYS = ("cloud", "hand_state", "robot_state", "previous_action", "goal")
GOAL_DIM = 9  # position (3) + the first two columns of the rotation (6)


class StudentObservations(LeafSystem):
    def __init__(self, num_points: int, cloud_noise_std: float, goal_noise_std: float):
        super().__init__()
        for name, std in (("cloud_noise_std", cloud_noise_std), ("goal_noise_std", goal_noise_std)):
            if not std >= 0:  # also rejects NaN
                raise InputError(f"observation.{name} must be >= 0 (metres), got {std}")
        self._cloud_std, self._goal_std = float(cloud_noise_std), float(goal_noise_std)
        n3 = 3 * num_points
        self.DeclareVectorInputPort("points", n3)
        self.DeclareVectorInputPort("cloud_unit_noise", n3)
        self.DeclareVectorInputPort("goal_unit_noise", 3)
        self.DeclareVectorInputPort("hand_state", 9)
        self.DeclareVectorInputPort("robot_state", 2 * NUM_JOINTS)
        self.DeclareVectorInputPort("previous_action", ACTION_DIM)
        self.DeclareVectorInputPort("estimated_goal", GOAL_DIM)
        self.DeclareVectorOutputPort("cloud", n3, self._calc_cloud)
        self.DeclareVectorOutputPort("goal", GOAL_DIM, self._calc_goal)
        for key, port, size in (("hand_state", "hand_state", 9),
                                ("robot_state", "robot_state", 2 * NUM_JOINTS),
                                ("previous_action", "previous_action", ACTION_DIM)):
            self.DeclareVectorOutputPort(key, size, self._copier(port))

    def _copier(self, port_name):
        def calc(context, output):
            output.SetFromVector(self.GetInputPort(port_name).Eval(context))
        return calc

    def _calc_cloud(self, context, output):
        pts = self.GetInputPort("points").Eval(context)
        if self._cloud_std > 0:
            pts = pts + self._cloud_std * self.GetInputPort("cloud_unit_noise").Eval(context)
        output.SetFromVector(pts)

    def _calc_goal(self, context, output):
        goal = self.GetInputPort("estimated_goal").Eval(context).copy()
        if self._goal_std > 0:
            # Position only: the paper's goal-pose noise is on the normalised input, and the
            # normalisation (/0.4) only applies to positions.
            goal[:3] += self._goal_std * self.GetInputPort("goal_unit_noise").Eval(context)
        output.SetFromVector(goal)
