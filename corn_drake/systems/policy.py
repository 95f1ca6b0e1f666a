"""PolicySystem: the learned policy as a LeafSystem that closes the loop inside a diagram.

Input: the packed `observation` of TeacherObservations (ObservationLayout unpacks it); output
`action` (20, normalised, the deterministic Gaussian mean clipped to [-1, 1]). The action is a cached
feed-through output, so the policy network runs only when ActionToJointTargets latches it at
the policy rate — once per 0.1 s — and sees the observation of that instant, exactly as the
gymnasium path does.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from corn_drake.systems.ik import ACTION_DIM
from corn_drake.systems.observations import ObservationLayout


class PolicySystem(LeafSystem):
    def __init__(self, agent, num_points: int = 512):
        super().__init__()
        self._agent = agent
        self._layout = ObservationLayout(num_points)
        self._obs = self.DeclareVectorInputPort("observation", self._layout.size)
        self.DeclareVectorOutputPort("action", ACTION_DIM, self._calc_action)

    def observation(self, context) -> dict[str, np.ndarray]:
        return self._layout.unpack(self._obs.Eval(context))

    def _calc_action(self, context, output: BasicVector):
        output.SetFromVector(self._agent.act(self.observation(context)))
