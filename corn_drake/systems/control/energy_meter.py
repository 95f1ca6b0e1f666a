"""Actuation energy sum_k sum_j |tau_j qdot_j| accumulated over physics steps, without Python.

The reward's energy penalty needs the torque-power at every physics step. A Python update per
physics step would cost as much as the torque law itself (measured: env/bare overhead 2.2x with
it), so the meter is a Multiplexer feeding a discrete SymbolicVectorSystem (evaluated in C++):
e[k+1] = e[k] + sum_j |tau_j qdot_j| at the physics period.

tau comes from the plant's net-actuation output (the torque the plant applied in the step that
led to the current state), not from the controller's output port: evaluating the controller here
made Drake run the Python torque law twice per physics step. The sum over a policy step is thus
shifted by one physics step, which the penalty does not care about.
"""

from __future__ import annotations

from pydrake.symbolic import MakeVectorVariable, Variable, abs as sym_abs
from pydrake.systems.framework import DiagramBuilder, OutputPort
from pydrake.systems.primitives import Multiplexer, SymbolicVectorSystem

from corn_drake.contract import NUM_JOINTS, ROBOT_STATE_DIM


def add_energy_meter(builder: DiagramBuilder, actuation: OutputPort, robot_state: OutputPort,
                     time_step: float, name: str = "energy_meter"):
    """Returns (energy output port (1), the meter system whose state is the energy)."""
    n = NUM_JOINTS
    # The Multiplexer's inputs are positional: [tau (n), robot_state = (q (n), qdot (n))].
    inputs = (actuation, robot_state)
    mux = builder.AddNamedSystem(f"{name}.inputs", Multiplexer([n, ROBOT_STATE_DIM]))
    e = Variable("energy")
    u = MakeVectorVariable(n + ROBOT_STATE_DIM, "u")
    tau, qdot = u[:n], u[2 * n:]
    power = sum(sym_abs(tau[j] * qdot[j]) for j in range(n))
    meter = builder.AddNamedSystem(name, SymbolicVectorSystem(
        state=[e], input=u, dynamics=[e + power], output=[e], time_period=time_step))
    for i, port in enumerate(inputs):
        builder.Connect(port, mux.get_input_port(i))
    builder.Connect(mux.get_output_port(), meter.get_input_port())
    return meter.get_output_port(), meter
