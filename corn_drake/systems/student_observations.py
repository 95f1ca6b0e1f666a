"""StudentObservations: what the student policy sees, one output per key.

cloud (512 x 3, flattened): the segmented partial cloud plus N(0, cloud_noise_std) noise per
coordinate (the authors' PerturbCloud). goal (9): the goal relative to the tracker's *estimated*
pose, not the true one, with N(0, goal_noise_std) noise on its position (first 3 entries).
Both stds are in metres (StudentObservationConfig converts the paper's normalised-unit
numbers). The unit noise comes in on ``cloud_unit_noise`` / ``goal_unit_noise`` from Drake
RandomSources, seeded through the context like any other random input
(diagrams.reseed_random_sources draws fresh seeds per episode).
hand_state, robot_state, previous_action: as the teacher's. Keys and sizes are the contract's
(STUDENT_OBS_KEYS, observation_size).
"""

from __future__ import annotations

from pydrake.systems.framework import LeafSystem

from corn_drake.contract import (GOAL_DIM, POSE9_POSITION, POSITION_DIM, STUDENT_OBS_KEYS,
                                 observation_size)
from corn_drake.errors import InputError

# Copied through unchanged from the teacher-side signals of the same name.
PASSED_THROUGH = ("hand_state", "robot_state", "previous_action")


class StudentObservations(LeafSystem):
    def __init__(self, num_points: int, cloud_noise_std: float, goal_noise_std: float):
        super().__init__()
        for name, std in (("cloud_noise_std", cloud_noise_std), ("goal_noise_std", goal_noise_std)):
            if not std >= 0:  # also rejects NaN
                raise InputError(f"observation.{name} must be >= 0 (metres), got {std}")
        self._cloud_std, self._goal_std = float(cloud_noise_std), float(goal_noise_std)
        size = {k: observation_size(k, num_points) for k in STUDENT_OBS_KEYS}
        self._points = self.DeclareVectorInputPort("points", size["cloud"])
        self._cloud_noise = self.DeclareVectorInputPort("cloud_unit_noise", size["cloud"])
        self._goal_noise = self.DeclareVectorInputPort("goal_unit_noise", POSITION_DIM)
        passed = {k: self.DeclareVectorInputPort(k, size[k]) for k in PASSED_THROUGH}
        self._estimated_goal = self.DeclareVectorInputPort("estimated_goal", GOAL_DIM)
        calc = {"cloud": self._calc_cloud, "goal": self._calc_goal}
        for key in STUDENT_OBS_KEYS:
            self.DeclareVectorOutputPort(key, size[key], calc.get(key) or self._copier(passed[key]))

    @staticmethod
    def _copier(port):
        def calc(context, output):
            output.SetFromVector(port.Eval(context))
        return calc

    def _calc_cloud(self, context, output):
        pts = self._points.Eval(context)
        if self._cloud_std > 0:
            pts = pts + self._cloud_std * self._cloud_noise.Eval(context)
        output.SetFromVector(pts)

    def _calc_goal(self, context, output):
        goal = self._estimated_goal.Eval(context).copy()
        if self._goal_std > 0:
            # Position only: the paper's goal-pose noise is on the normalised input, and the
            # normalisation only applies to positions.
            goal[POSE9_POSITION] += self._goal_std * self._goal_noise.Eval(context)
        output.SetFromVector(goal)
