"""PolicySystem: the learned policy as a LeafSystem that closes the loop inside a diagram.

Inputs: one port per observation key (the TeacherObservations outputs); output `action` (20,
normalised, the deterministic Gaussian mean clipped to [-1, 1]). The action is a cached
feed-through output, so the policy network runs only when ActionToJointTargets latches it at
the policy rate — once per 0.1 s — and sees the observation of that instant, exactly as the
gymnasium path does.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from corn_drake.systems.ik import ACTION_DIM

OBS_SIZES = {"cloud": None, "hand_state": 9, "robot_state": 14, "previous_action": ACTION_DIM,
             "goal": 9, "physics": 5, "object_keypoints": 24}


class PolicySystem(LeafSystem):
    def __init__(self, agent, num_points: int = 512):
        super().__init__()
        self._agent = agent
        self._n = num_points
        self._ports = {}
        for key, size in OBS_SIZES.items():
            self._ports[key] = self.DeclareVectorInputPort(key, size or 3 * num_points)
        self.DeclareVectorOutputPort("action", ACTION_DIM, self._calc_action)

    def observation(self, context) -> dict[str, np.ndarray]:
        obs = {k: np.asarray(p.Eval(context), np.float32) for k, p in self._ports.items()}
        obs["cloud"] = obs["cloud"].reshape(self._n, 3)
        return obs

    def _calc_action(self, context, output: BasicVector):
        output.SetFromVector(self._agent.act(self.observation(context)))
