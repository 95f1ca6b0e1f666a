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

With `attention` (policies that cross-attend over patches: corn, e2e), two more outputs say what
the policy attended to when it chose the action: `attention` (the per-patch scores, summing to
1; nn/attention.py) and `point_attention` (each cloud point's patch score, for painting). The
action and the attention come from one forward pass (TeacherAgent.act_and_attend) held in a
cache entry that all three outputs read, so the network still runs once per policy step, on the
observation of that instant, whichever output is evaluated first.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem, ValueProducer

from corn_drake.contract import ACTION_DIM, DEFAULT_NUM_POINTS
from corn_drake.systems.observations import ObservationLayout


class PolicySystem(LeafSystem):
    def __init__(self, agent, num_points: int = DEFAULT_NUM_POINTS, stochastic: bool = False,
                 attention: bool = False):
        """`agent.act(obs)` gives the mean action; with `stochastic`, the system calls
        `agent.act(obs, unit_noise)` instead (rl/ppo/agent.TeacherAgent.act). With `attention`,
        `agent.act_and_attend` gives the action and the attention outputs."""
        super().__init__()
        if attention and not getattr(agent, "has_attention", False):
            raise ValueError(f"PolicySystem(attention=True): policy "
                             f"{getattr(agent, 'kind', type(agent).__name__)!r} has no "
                             "cross-attention over patches (only corn, e2e, p2v-lite and rot have one)")
        self._agent = agent
        self._layout = ObservationLayout(num_points)
        self._obs = self.DeclareVectorInputPort("observation", self._layout.size)
        self._unit_noise = (self.DeclareVectorInputPort("unit_noise", ACTION_DIM)
                            if stochastic else None)
        if not attention:
            self.DeclareVectorOutputPort("action", ACTION_DIM, self._calc_action)
            return
        inputs = {self.input_port_ticket(port.get_index())
                  for port in (self._obs, self._unit_noise) if port is not None}
        self._step = self.DeclareCacheEntry(
            "policy step: (action, PatchAttention)",
            ValueProducer(allocate=lambda: AbstractValue.Make(None), calc=self._calc_step),
            inputs)
        step = {self._step.ticket()}
        self.DeclareVectorOutputPort("action", ACTION_DIM, self._output(lambda s: s[0]),
                                     prerequisites_of_calc=step)
        self.DeclareVectorOutputPort("attention", agent.encoder.network.num_patches,
                                     self._output(lambda s: s[1].patch_scores),
                                     prerequisites_of_calc=step)
        self.DeclareVectorOutputPort("point_attention", num_points,
                                     self._output(lambda s: s[1].point_scores()),
                                     prerequisites_of_calc=step)

    @property
    def stochastic(self) -> bool:
        return self._unit_noise is not None

    def observation(self, context) -> dict[str, np.ndarray]:
        return self._layout.unpack(self._obs.Eval(context))

    def _calc_action(self, context, output: BasicVector):
        obs = self.observation(context)
        # Deterministic: act(obs) alone, the call the reference controllers (rl/scripted.py) take.
        if self._unit_noise is None:
            output.SetFromVector(self._agent.act(obs))
        else:
            output.SetFromVector(self._agent.act(obs, self._unit_noise.Eval(context)))

    def _calc_step(self, context, value):
        noise = None if self._unit_noise is None else self._unit_noise.Eval(context)
        value.set_value(self._agent.act_and_attend(self.observation(context), noise))

    def _output(self, field):
        def calc(context, output: BasicVector):
            output.SetFromVector(field(self._step.Eval(context)))

        return calc
