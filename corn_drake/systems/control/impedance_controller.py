"""The per-physics-step joint torque law of the variable-impedance controller.

tau = kp * (q_target - q) - kd * qdot (+ std * unit noise), clamped to the effort limits,
with kd = rho * sqrt(kp) supplied by ActionToJointTargets. There is no gravity term: the robot's
gravity is disabled in the plant, as in the paper's simulation.

`impedance_torque` is the law, written once for numpy arrays and for pydrake.symbolic
Expressions. Two systems run it:
  * VariableImpedanceController: a Python LeafSystem (readable reference, easy to extend);
  * make_symbolic_impedance_controller: the same law compiled into a SymbolicVectorSystem (a C++
    LeafSystem) behind a Multiplexer. This is the only code that runs at every physics step, and
    a Python callback there costs ~37 us per step (trampoline + numpy), ~15 % of bare physics;
    the symbolic one costs a few us. Both have the same ports; tests check they agree.
Ports: inputs robot_state (14), q_target (7), gains (14: kp, kd), noise_std (1) and, when built
with noise, unit_noise (7, N(0,1) per physics step); output actuation (7).
"""

from __future__ import annotations

import numpy as np
from pydrake.symbolic import MakeVectorVariable, max as sym_max, min as sym_min
from pydrake.systems.framework import BasicVector, Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import Multiplexer, SymbolicVectorSystem

from corn_drake.contract import NUM_JOINTS, ROBOT_STATE_DIM

N = NUM_JOINTS


def impedance_torque(q, v, q_target, kp, kd, limits, clip, noise=None):
    """The torque law on numpy arrays or arrays of symbolic Expressions; `clip(x, lo, hi)`."""
    tau = kp * (q_target - q) - kd * v
    if noise is not None:
        tau = tau + noise
    return clip(tau, -limits, limits)


def _symbolic_clip(x, lo, hi):
    return np.array([sym_min(sym_max(xi, lo_i), hi_i) for xi, lo_i, hi_i in zip(x, lo, hi)])


def _check_limits(effort_limits) -> np.ndarray:
    limits = np.asarray(effort_limits, float)
    if limits.shape != (N,):
        raise ValueError(f"effort_limits needs {N} values, got {limits.shape}")
    return limits


class VariableImpedanceController(LeafSystem):
    def __init__(self, effort_limits, with_noise: bool = False):
        super().__init__()
        self._limits = _check_limits(effort_limits)
        self._with_noise = with_noise
        self._robot_state = self.DeclareVectorInputPort("robot_state", ROBOT_STATE_DIM)
        self._q_target = self.DeclareVectorInputPort("q_target", N)
        self._gains = self.DeclareVectorInputPort("gains", 2 * N)
        self._noise_std = self.DeclareVectorInputPort("noise_std", 1)
        if with_noise:
            self._unit_noise = self.DeclareVectorInputPort("unit_noise", N)
        self.DeclareVectorOutputPort("actuation", N, self._calc_tau)

    def _calc_tau(self, context, output: BasicVector):
        x = self._robot_state.Eval(context)
        gains = self._gains.Eval(context)
        noise = None
        if self._with_noise:
            noise = self._noise_std.Eval(context)[0] * self._unit_noise.Eval(context)
        output.SetFromVector(impedance_torque(x[:N], x[N:], self._q_target.Eval(context),
                                              gains[:N], gains[N:], self._limits, np.clip, noise))


def make_symbolic_impedance_controller(effort_limits, with_noise: bool = False) -> Diagram:
    """The same law as a C++ SymbolicVectorSystem, with VariableImpedanceController's ports."""
    limits = _check_limits(effort_limits)
    inputs = {"robot_state": ROBOT_STATE_DIM, "q_target": N, "gains": 2 * N, "noise_std": 1}
    if with_noise:
        inputs["unit_noise"] = N
    sizes = list(inputs.values())
    u = MakeVectorVariable(sum(sizes), "u")
    part = dict(zip(inputs, np.split(u, np.cumsum(sizes)[:-1])))
    x, q_target, gains, std = part["robot_state"], part["q_target"], part["gains"], part["noise_std"]
    # numpy reports floating-point flags that Drake's symbolic arithmetic leaves set as
    # "invalid value" warnings on object arrays; the expressions themselves are exact.
    with np.errstate(invalid="ignore"):
        noise = std[0] * part["unit_noise"] if with_noise else None
        tau = impedance_torque(x[:N], x[N:], q_target, gains[:N], gains[N:], limits,
                               _symbolic_clip, noise)
    builder = DiagramBuilder()
    mux = builder.AddNamedSystem("inputs", Multiplexer(sizes))
    law = builder.AddNamedSystem("torque_law", SymbolicVectorSystem(input=u, output=tau))
    builder.Connect(mux.get_output_port(), law.get_input_port())
    # The Multiplexer's inputs are positional, in `inputs` order; the diagram names them.
    for i, name in enumerate(inputs):
        builder.ExportInput(mux.get_input_port(i), name)
    builder.ExportOutput(law.get_output_port(), "actuation")
    return builder.Build()


def make_impedance_controller(effort_limits, with_noise: bool = False, backend: str = "symbolic"):
    if backend == "symbolic":
        return make_symbolic_impedance_controller(effort_limits, with_noise)
    if backend == "python":
        return VariableImpedanceController(effort_limits, with_noise)
    raise ValueError(f"controller.torque_backend must be 'symbolic' or 'python', got {backend!r}")
