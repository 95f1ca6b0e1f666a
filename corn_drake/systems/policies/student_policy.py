"""StudentPolicySystem: the recurrent student policy as a LeafSystem that closes the loop inside
the student diagram (evaluation), with its GRU state held in the context.

Inputs: the student observation as StudentObservations produces it, one port per key of
contract.STUDENT_OBS_KEYS (cloud flattened); with `stochastic`, also `unit_noise` (ACTION_DIM
draws of N(0, 1) from a RandomSource sampling at the policy period, as for PolicySystem).
Output `action` (ACTION_DIM, normalised, clipped to [-1, 1]): the Gaussian mean, or
mean + exp(log_std) * unit_noise. Output `hidden`: the GRU state h_t (layers x hidden,
flattened), for inspection.

The GRU state is discrete state, so it lives in the context like every other state: it is the
student's initial_state (zeros) in the default context, and DiagramEnv.reset restores the
default context before every episode (TeacherDiagram.write_episode), so no episode inherits
another's memory.

Timing: the hidden state is updated by a periodic discrete update at the policy clock's period
and offset, the same event time at which ActionToJointTargets latches the action. Drake computes
all discrete updates of one event time from the same context and applies them together, so the
latch reads action(obs_t, h_t) while this system's update writes h_{t+1}: never the action of
h_{t+1}. Both come from one network call: a cache entry holds (action, h_{t+1}) for the current
(inputs, h_t); the `action` output and the update read it, so the network runs once per step.
At policy step t this is exactly StudentPolicy.step(obs_t, h_t) of the training path.
"""

from __future__ import annotations

import numpy as np
import torch
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem, ValueProducer

from corn_drake.contract import ACTION_DIM, student_observation_shapes
from corn_drake.nn.policy import gaussian_action
from corn_drake.nn.threads import torch_threads
from corn_drake.timing import PolicyClock


class StudentPolicySystem(LeafSystem):
    def __init__(self, student, num_points: int, clock: PolicyClock, stochastic: bool = False):
        """`student`: a StudentPolicy (nn/student.py) in eval mode; `num_points`: the
        segmented cloud's size (segmentation.num_points); `clock`: the diagram's policy clock."""
        super().__init__()
        if student.training:
            # Dropout in train mode would make the evaluation's actions random.
            raise ValueError("StudentPolicySystem: put the student in eval mode (student.eval())")
        self._student = student
        self._shapes = student_observation_shapes(num_points)
        self._obs = {k: self.DeclareVectorInputPort(k, int(np.prod(s)))
                     for k, s in self._shapes.items()}
        self._unit_noise = (self.DeclareVectorInputPort("unit_noise", ACTION_DIM)
                            if stochastic else None)
        initial = student.initial_state(1)
        self._hidden_shape = tuple(initial.shape)
        self._hidden = self.DeclareDiscreteState(initial.double().numpy().reshape(-1))
        self.DeclarePeriodicDiscreteUpdateEvent(clock.period, clock.offset, self._advance)
        # (action, next hidden) of the current inputs and hidden state: one network call serves
        # the action output and the state update of the same event.
        size = ACTION_DIM + int(np.prod(self._hidden_shape))
        self._step = self.DeclareCacheEntry(
            "student step: action and next GRU state",
            ValueProducer(allocate=lambda: AbstractValue.Make(BasicVector(size)),
                          calc=self._calc_step),
            {self.all_input_ports_ticket(), self.xd_ticket()})
        self.DeclareVectorOutputPort("action", ACTION_DIM, self._calc_action,
                                     {self._step.ticket()})
        self.DeclareStateOutputPort("hidden", self._hidden)

    @property
    def stochastic(self) -> bool:
        return self._unit_noise is not None

    def observation(self, context) -> dict[str, np.ndarray]:
        """The student observation on the input ports, shaped as StudentEnv returns it."""
        return {k: np.asarray(p.Eval(context), np.float32).reshape(self._shapes[k])
                for k, p in self._obs.items()}

    def hidden_state(self, context) -> torch.Tensor:
        """The GRU state h_t in `context` (this system's), shaped (layers, 1, hidden)."""
        value = context.get_discrete_state(self._hidden).value()
        return torch.tensor(value, dtype=torch.float32).reshape(self._hidden_shape)

    def _calc_step(self, context, value) -> None:
        obs = {k: torch.from_numpy(v)[None] for k, v in self.observation(context).items()}
        # One observation at a time gains nothing from intra-op threads, and in this process
        # Open3D's OpenMP workers (the ICP tracker) spin while torch's wait: one step of the
        # student measured 140-330 ms with torch's 2 threads here, 5 ms with 1.
        with torch_threads(1), torch.no_grad():
            mean, hidden = self._student.step(obs, self.hidden_state(context))
            noise = (None if self._unit_noise is None
                     else torch.as_tensor(np.asarray(self._unit_noise.Eval(context))))
            action = gaussian_action(mean, self._student.log_std, noise)
        value.get_mutable_value().SetFromVector(np.concatenate(
            [action.double().numpy().reshape(-1), hidden.double().numpy().reshape(-1)]))

    def _step_value(self, context) -> np.ndarray:
        return self._step.Eval(context).get_value()

    def _calc_action(self, context, output: BasicVector) -> None:
        output.SetFromVector(self._step_value(context)[:ACTION_DIM])

    def _advance(self, context, discrete_state) -> None:
        discrete_state.set_value(self._hidden, self._step_value(context)[ACTION_DIM:])
