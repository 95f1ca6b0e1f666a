"""PrimitivePolicySystem: the contact-primitive policy as a LeafSystem feeding PrimitiveExecutor.

Inputs: `observation` (TeacherObservations' packed output), `normals` (the cloud's world
normals, ObjectSurface), `object_position` (3) and `executor_status` (the executor's status).
Outputs:
  primitive  PRIMITIVE_DIM: the policy's choice for the observation of this instant, numbered
             (executor's count + 1) so the executor starts it when it is idle;
  choice     (CHOICE_DIM): [cloud index of the chosen point, location index, motion (3)] of
             the last primitive the executor took (-1 before the first);
  scores     (L,): the policy's score of every candidate location at that choice.
The network runs only when `primitive` is evaluated, and the executor evaluates it only when
idle: one forward pass per primitive. `choice` and `scores` are held in discrete state, written
at the tick the executor takes the primitive from the same cached pass, so displays reading
them every step cost nothing. The
primitive's point and normal are looked up in the same observation the policy saw, as the
gymnasium env (rl/envs/primitive_env.py) does for an action, so the evaluation diagram and the env
run the same primitive for the same choice.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem, ValueProducer

from corn_drake.contract import POSITION_DIM
from corn_drake.contract import PRIMITIVE_CHOICE_DIM as CHOICE_DIM
from corn_drake.systems.control.low_push import push_contact
from corn_drake.systems.observations import ObservationLayout
from corn_drake.systems.control.primitive_executor import (IDLE, PRIMITIVE_DIM, STATUS_DIM,
                                                   STATUS_LAYOUT, make_primitive)
from corn_drake.timing import PolicyClock



class PrimitivePolicySystem(LeafSystem):
    def __init__(self, agent, num_points: int, clock: PolicyClock):
        super().__init__()
        self._agent = agent
        self._layout = ObservationLayout(num_points)
        self._obs = self.DeclareVectorInputPort("observation", self._layout.size)
        self._normals = self.DeclareVectorInputPort("normals", POSITION_DIM * num_points)
        self._position = self.DeclareVectorInputPort("object_position", POSITION_DIM)
        self._status = self.DeclareVectorInputPort("executor_status", STATUS_DIM)
        self._choice = self.DeclareCacheEntry(
            "policy choice", ValueProducer(allocate=lambda: AbstractValue.Make(None),
                                           calc=self._calc_choice),
            {self.input_port_ticket(p.get_index())
             for p in (self._obs, self._normals, self._position)})
        self.DeclareVectorOutputPort("primitive", PRIMITIVE_DIM, self._calc_primitive,
                                     {self._choice.ticket(),
                                      self.input_port_ticket(self._status.get_index())})
        # The last choice the executor took (recorded at the tick it took it, from the same
        # cached forward pass), held for displays and tests: [cloud index, location index,
        # motion (3), scores (L)]. Reading it never runs the network.
        self._held = self.DeclareDiscreteState(
            np.full(CHOICE_DIM + agent.location_count(), -1.0))
        self.DeclarePeriodicDiscreteUpdateEvent(clock.period, clock.offset, self._record)
        held = {self.discrete_state_ticket(self._held)}
        self.DeclareVectorOutputPort("choice", CHOICE_DIM, self._held_slice(0, CHOICE_DIM), held)
        self.DeclareVectorOutputPort("scores", agent.location_count(),
                                     self._held_slice(CHOICE_DIM, None), held)

    def observation(self, context) -> dict[str, np.ndarray]:
        obs = self._layout.unpack(self._obs.Eval(context))
        obs["normals"] = np.asarray(self._normals.Eval(context), np.float32).reshape(
            -1, POSITION_DIM)
        obs["object_position"] = np.asarray(self._position.Eval(context), np.float32)
        return obs

    def _calc_choice(self, context, value):
        obs = self.observation(context)
        choice = self._agent.choose(obs)
        # Where the push aims (the chosen point, or lowered: systems/control/low_push.py).
        choice["point_xyz"], choice["normal"] = push_contact(
            obs["cloud"], obs["normals"], choice["point"], self._agent.primitive_config)
        value.set_value(choice)

    def _calc_primitive(self, context, output: BasicVector):
        c = self._choice.Eval(context)
        count = int(round(self._status.Eval(context)[STATUS_LAYOUT["count"]]))
        output.SetFromVector(make_primitive(c["point_xyz"], c["normal"], c["motion"],
                                            c["point"], count + 1))

    def _record(self, context, discrete_state):
        # The executor takes a primitive at a tick where it is idle (its status before the
        # tick): record the choice it reads at that same tick.
        if self._status.Eval(context)[STATUS_LAYOUT["phase"]] != IDLE:
            return
        c = self._choice.Eval(context)
        discrete_state.set_value(self._held, np.concatenate(
            [[c["point"], c["location"]], c["motion"], c["scores"]]))

    def _held_slice(self, start: int, stop):
        def calc(context, output: BasicVector):
            output.SetFromVector(context.get_discrete_state(self._held).value()[start:stop])

        return calc
