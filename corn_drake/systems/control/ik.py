"""ActionToJointTargets: once per policy step, turns the action into joint targets and gains.

Action (normalised to [-1, 1], layout contract.ACTION_SLICES): EE residual dx (3, world frame),
axis-angle dr (3, world frame), kp (7) and damping ratio rho (7). The target EE position is clamped to +- ee_clamp around the
current EE and to the object's box +- (radius + object_margin); damped least squares gives
dq = J^T (J J^T + lambda I)^-1 e and q_target = q + dq.

The targets live in discrete state updated periodically at the policy rate (half a physics step
before the first plant update of a policy step, see corn_drake/timing.py), so they drive exactly
the 8 physics steps of that policy step.
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import BasicVector, LeafSystem

from corn_drake.config.scene import ControllerConfig
from corn_drake.contract import (ACTION_DIM, ACTION_SLICES, FREE_BODY_POSITION,
                                 FREE_BODY_STATE_DIM, ROBOT_STATE_DIM, check_action)
from corn_drake.scene.franka import NUM_JOINTS, make_controller_plant, tool_frame
from corn_drake.timing import PolicyClock


class ActionScaling:
    """Normalised action in [-1, 1] <-> physical action (dx, dr, kp, rho)."""

    def __init__(self, cfg: ControllerConfig):
        ranges = {"position": (-cfg.max_position_delta, cfg.max_position_delta),
                  "rotation": (-cfg.max_rotation_delta, cfg.max_rotation_delta),
                  "kp": cfg.kp_range, "rho": cfg.rho_range}
        lo, hi = np.empty(ACTION_DIM), np.empty(ACTION_DIM)
        for name, part in ACTION_SLICES.items():
            lo[part], hi[part] = ranges[name]
        self.low, self.high = lo, hi
        self.center, self.half_range = (hi + lo) / 2, (hi - lo) / 2

    def to_physical(self, action: np.ndarray) -> np.ndarray:
        return self.center + self.half_range * np.clip(action, -1.0, 1.0)


class ActionToJointTargets(LeafSystem):
    def __init__(self, cfg: ControllerConfig, clock: PolicyClock, robot_base: np.ndarray,
                 armature=None):
        super().__init__()
        self._cfg = cfg
        self._scaling = ActionScaling(cfg)
        self._plant = make_controller_plant(armature)
        self._plant_context = self._plant.CreateDefaultContext()
        self._tool = tool_frame(self._plant)
        self._base = np.asarray(robot_base, float)
        n = NUM_JOINTS
        self._action = self.DeclareVectorInputPort("action", ACTION_DIM)
        self._robot_state = self.DeclareVectorInputPort("robot_state", ROBOT_STATE_DIM)
        self._object_state = self.DeclareVectorInputPort("object_state", FREE_BODY_STATE_DIM)
        self._object_radius = self.DeclareVectorInputPort("object_radius", 1)
        # [q_target (7), kp (7), kd (7), previous physical action (20)]
        self._state = self.DeclareDiscreteState(3 * n + ACTION_DIM)
        self.DeclarePeriodicDiscreteUpdateEvent(clock.period, clock.offset, self._latch)
        self.DeclareStateOutputPort("latched", self._state)
        self.DeclareVectorOutputPort("q_target", n, self._calc_q_target, {self.discrete_state_ticket(self._state)})
        self.DeclareVectorOutputPort("gains", 2 * n, self._calc_gains, {self.discrete_state_ticket(self._state)})
        self.DeclareVectorOutputPort("previous_action", ACTION_DIM, self._calc_prev,
                                     {self.discrete_state_ticket(self._state)})

    # --- state helpers -----------------------------------------------------------------------
    def hold_position(self, context, q: np.ndarray) -> None:
        """Resets the latch: hold q with mid-range gains and a zero previous action."""
        kp = np.full(NUM_JOINTS, np.mean(self._cfg.kp_range))
        kd = np.mean(self._cfg.rho_range) * np.sqrt(kp)
        context.SetDiscreteState(self._state, np.concatenate([q, kp, kd, np.zeros(ACTION_DIM)]))

    def ee_pose(self, q: np.ndarray):
        """Tool pose in the robot-base frame for joint angles q."""
        self._plant.SetPositions(self._plant_context, q)
        return self._plant.CalcRelativeTransform(self._plant_context, self._plant.world_frame(),
                                                 self._tool)

    def targets(self, action: np.ndarray, q: np.ndarray, object_position: np.ndarray,
                object_radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(q_target, kp, kd, physical action) for a normalised action at joint angles q."""
        cfg = self._cfg
        phys = self._scaling.to_physical(check_action(action))
        X_BT = self.ee_pose(q)
        p_ee = X_BT.translation()
        target = p_ee + phys[ACTION_SLICES["position"]]
        obj = np.asarray(object_position) - self._base
        reach = object_radius + cfg.object_margin
        target = np.clip(target, obj - reach, obj + reach)
        target = np.clip(target, p_ee - cfg.ee_clamp, p_ee + cfg.ee_clamp)
        e = np.concatenate([target - p_ee, phys[ACTION_SLICES["rotation"]]])
        # Rows: angular then translational velocity of the tool frame (Drake's spatial order).
        J = self._plant.CalcJacobianSpatialVelocity(
            self._plant_context, JacobianWrtVariable.kQDot, self._tool, np.zeros(3),
            self._plant.world_frame(), self._plant.world_frame())
        J = np.vstack([J[3:], J[:3]])  # -> [linear; angular] to match e
        dq = J.T @ np.linalg.solve(J @ J.T + cfg.ik_damping * np.eye(6), e)
        kp = phys[ACTION_SLICES["kp"]]
        kd = phys[ACTION_SLICES["rho"]] * np.sqrt(kp)
        return q + dq, kp, kd, phys

    # --- events and outputs ------------------------------------------------------------------
    def _latch(self, context, discrete_state):
        x = self._robot_state.Eval(context)
        q_t, kp, kd, phys = self.targets(self._action.Eval(context), x[:NUM_JOINTS],
                                         self._object_state.Eval(context)[FREE_BODY_POSITION],
                                         float(self._object_radius.Eval(context)[0]))
        discrete_state.set_value(self._state, np.concatenate([q_t, kp, kd, phys]))

    def _calc_q_target(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._state).value()[:NUM_JOINTS])

    def _calc_gains(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._state).value()[NUM_JOINTS:3 * NUM_JOINTS])

    def _calc_prev(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._state).value()[3 * NUM_JOINTS:])
