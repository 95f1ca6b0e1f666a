"""VariableImpedanceController: the per-physics-step joint torque law.

tau = kp * (q_target - q) - kd * qdot (+ optional torque noise), clamped to the effort limits,
with kd = rho * sqrt(kp) supplied by ActionToJointTargets. There is no gravity term: the robot's
gravity is disabled in the plant, as in the paper's simulation.

This is the only Python code that runs at every physics step; the energy bookkeeping the reward
needs is done by C++ primitives (systems/energy_meter.py).
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from corn_drake.scene.franka import NUM_JOINTS


class VariableImpedanceController(LeafSystem):
    def __init__(self, effort_limits, with_noise: bool = False):
        super().__init__()
        n = NUM_JOINTS
        self._limits = np.asarray(effort_limits, float)
        if self._limits.shape != (n,):
            raise ValueError(f"effort_limits needs {n} values")
        self.DeclareVectorInputPort("robot_state", 2 * n)
        self.DeclareVectorInputPort("q_target", n)
        self.DeclareVectorInputPort("gains", 2 * n)
        self._with_noise = with_noise
        if with_noise:
            self.DeclareVectorInputPort("unit_noise", n)  # N(0, 1) per physics step
        # Noise std (N m) is a numeric parameter so domain randomization can set it per episode.
        self._noise_param = self.DeclareNumericParameter(BasicVector([0.0]))
        self.DeclareVectorOutputPort("actuation", n, self._calc_tau)

    def set_noise_std(self, context, std: float) -> None:
        if std > 0 and not self._with_noise:
            raise ValueError("torque noise requested but the controller was built without noise")
        context.get_mutable_numeric_parameter(self._noise_param).SetAtIndex(0, std)

    def torque(self, context) -> np.ndarray:
        n = NUM_JOINTS
        x = self.get_input_port(0).Eval(context)
        gains = self.get_input_port(2).Eval(context)
        tau = gains[:n] * (self.get_input_port(1).Eval(context) - x[:n]) - gains[n:] * x[n:]
        if self._with_noise:
            std = context.get_numeric_parameter(self._noise_param).GetAtIndex(0)
            tau = tau + std * self.get_input_port(3).Eval(context)
        return np.clip(tau, -self._limits, self._limits)

    def _calc_tau(self, context, output: BasicVector):
        output.SetFromVector(self.torque(context))
