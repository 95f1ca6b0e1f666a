"""PolicySystem: the learned policy as a LeafSystem that closes the loop inside a diagram.

Input: the packed `observation` of TeacherObservations (ObservationLayout unpacks it); output
`action` (ACTION_DIM, normalised, clipped to [-1, 1]). The action is a cached feed-through
output, so the policy network runs only when ActionToJointTargets latches it at the policy rate
— once per policy period — and sees the observation of that instant, exactly as the gymnasium
path does.

Deterministic (the default): the action is the policy's Gaussian mean. Stochastic: the system
has a second input, `unit_noise` (ACTION_DIM draws of N(0, 1), from a RandomSource sampling at
the policy period, see diagrams.build_teacher_diagram), and acts
mean + exp(log_std) * unit_noise. The randomness lives in the diagram's context like every
other random input, so reseeding the diagram's RandomSources (diagrams.reseed_random_sources,
once per episode) makes an episode a function of its seed; the agent holds no random state.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from corn_drake.contract import ACTION_DIM, DEFAULT_NUM_POINTS
from corn_drake.systems.observations import ObservationLayout


class PolicySystem(LeafSystem):
    def __init__(self, agent, num_points: int = DEFAULT_NUM_POINTS, stochastic: bool = False):
        """`agent.act(obs)` gives the mean action; with `stochastic`, the system calls
        `agent.act(obs, unit_noise)` instead (rl/agent.TeacherAgent.act)."""
        super().__init__()
        self._agent = agent
        self._layout = ObservationLayout(num_points)
        self._obs = self.DeclareVectorInputPort("observation", self._layout.size)
        self._unit_noise = (self.DeclareVectorInputPort("unit_noise", ACTION_DIM)
                            if stochastic else None)
        self.DeclareVectorOutputPort("action", ACTION_DIM, self._calc_action)

    @property
    def stochastic(self) -> bool:
        return self._unit_noise is not None

    def observation(self, context) -> dict[str, np.ndarray]:
        return self._layout.unpack(self._obs.Eval(context))

    def _calc_action(self, context, output: BasicVector):
        obs = self.observation(context)
        if self._unit_noise is None:
            output.SetFromVector(self._agent.act(obs))
        else:
            output.SetFromVector(self._agent.act(obs, self._unit_noise.Eval(context)))
