"""TaskReward: the paper's potential-based reward and the success / out-of-workspace flags.

r = [g*Phi_obj(s') - Phi_obj(s)] + clip(g*Phi_hand(s') - Phi_hand(s), +-clip) - c_E * E
with Phi_obj the mean over the 8 bounding-box keypoints of k1 * 0.995^(k2 * |k_i - k_i_goal|)
(z translation ignored, full rotation kept), Phi_hand = k1_hand * 0.995^(k2 * |p_tool - p_obj|),
E the actuation energy of the policy step. On a success step the object term is replaced by +1.
The potentials and energy of the previous policy step are latched in discrete state.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from corn_drake.config import TaskConfig
from corn_drake.systems.observations import object_pose_from_state
from corn_drake.transforms import quat_wxyz_to_matrix, rotation_angle

STATUS_FIELDS = ("success", "out_of_workspace", "position_error", "orientation_error")


def keypoint_potential(corners, p, R, p_goal, R_goal, k1, k2) -> float:
    planar = np.array([1.0, 1.0, 0.0])
    cur = corners @ R.T + p * planar
    goal = corners @ R_goal.T + p_goal * planar
    return float(np.mean(k1 * 0.995 ** (k2 * np.linalg.norm(cur - goal, axis=1))))


def pose_errors(p, R, p_goal, R_goal) -> tuple[float, float]:
    """(planar xy distance, rotation angle) between the object and its goal."""
    return float(np.linalg.norm((p_goal - p)[:2])), rotation_angle(R_goal @ R.T)


class TaskReward(LeafSystem):
    def __init__(self, cfg: TaskConfig, policy_period: float):
        super().__init__()
        self._cfg = cfg
        self.DeclareVectorInputPort("object_state", 13)
        self.DeclareVectorInputPort("hand_state", 9)
        self.DeclareVectorInputPort("goal_pose", 7)
        self.DeclareVectorInputPort("object_keypoints", 24)
        self.DeclareVectorInputPort("energy", 1)
        # [Phi_obj, Phi_hand, energy] at the previous policy step.
        self._latched = self.DeclareDiscreteState(3)
        self.DeclarePeriodicDiscreteUpdateEvent(policy_period, 0.0, self._latch)
        self.DeclareVectorOutputPort("reward", 1, self._calc_reward)
        self.DeclareVectorOutputPort("task_status", len(STATUS_FIELDS), self._calc_status)

    def _poses(self, context):
        p, R = object_pose_from_state(self.get_input_port(0).Eval(context))
        g = self.get_input_port(2).Eval(context)
        return p, R, g[:3], quat_wxyz_to_matrix(g[3:])

    def potentials(self, context) -> tuple[float, float]:
        cfg = self._cfg
        p, R, p_goal, R_goal = self._poses(context)
        corners = self.get_input_port(3).Eval(context).reshape(8, 3)
        phi_obj = keypoint_potential(corners, p, R, p_goal, R_goal, cfg.keypoint_k1, cfg.keypoint_k2)
        tool = self.get_input_port(1).Eval(context)[:3]
        phi_hand = cfg.hand_k1 * 0.995 ** (cfg.keypoint_k2 * float(np.linalg.norm(tool - p)))
        return phi_obj, phi_hand

    def status(self, context) -> np.ndarray:
        cfg = self._cfg
        p, R, p_goal, R_goal = self._poses(context)
        pos_err, ori_err = pose_errors(p, R, p_goal, R_goal)
        success = pos_err <= cfg.success_position and ori_err <= cfg.success_orientation
        out = bool(np.any(p < cfg.workspace_low) or np.any(p >= cfg.workspace_high))
        return np.array([float(success), float(out), pos_err, ori_err])

    def reset(self, context) -> None:
        """Latches the current potentials and energy (call after setting the episode's state)."""
        context.SetDiscreteState(self._latched, [*self.potentials(context),
                                                 self.get_input_port(4).Eval(context)[0]])

    def _latch(self, context, discrete_state):
        discrete_state.set_value(self._latched, [*self.potentials(context),
                                                 self.get_input_port(4).Eval(context)[0]])

    def _calc_reward(self, context, output: BasicVector):
        cfg = self._cfg
        prev_obj, prev_hand, prev_energy = context.get_discrete_state(self._latched).value()
        phi_obj, phi_hand = self.potentials(context)
        success = self.status(context)[0] > 0
        obj_term = cfg.success_reward if success else cfg.potential_gamma * phi_obj - prev_obj
        hand_term = np.clip(cfg.potential_gamma * phi_hand - prev_hand, -cfg.hand_clip, cfg.hand_clip)
        energy = self.get_input_port(4).Eval(context)[0] - prev_energy
        output.SetFromVector([obj_term + hand_term - cfg.energy_coef * energy])

    def _calc_status(self, context, output: BasicVector):
        output.SetFromVector(self.status(context))
