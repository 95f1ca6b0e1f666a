"""TaskReward: the paper's potential-based reward and the success / out-of-workspace flags.

r = [g*Phi_obj(s') - Phi_obj(s)] + clip(g*Phi_hand(s') - Phi_hand(s), +-clip) - c_E * E
with Phi_obj the mean over the 8 bounding-box keypoints of k1 * 0.995^(k2 * |k_i - k_i_goal|)
(z translation ignored, full rotation kept), Phi_hand = k1_hand * 0.995^(k2 * |p_tool - p_obj|),
E the actuation "energy" of the policy step: sum_j |tau_j qdot_j| averaged over its physics steps
(the authors' E / 8 at 8 substeps). On a success step the object term is replaced by +1.

The previous policy step is remembered by a C++ ZeroOrderHold of [object_state, hand_state,
energy] at the policy period (add_task_reward wires it); the reward evaluates both potentials
when asked. A Python latch event did the same work every policy step whether or not anyone read
the reward, and cost ~0.12 ms per policy step.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem, OutputPort
from pydrake.systems.primitives import Multiplexer, ZeroOrderHold

from corn_drake.config.task import TaskConfig
from corn_drake.contract import (FREE_BODY_STATE_DIM, HAND_STATE_DIM, KEYPOINTS_DIM, POSE7_DIM,
                                 POSE7_POSITION, POSE7_QUATERNION, POSE9_POSITION, POSITION_DIM,
                                 free_body_pose)
from corn_drake.timing import PolicyClock
from corn_drake.transforms import quat_wxyz_to_matrix, rotation_angle

STATUS_FIELDS = ("success", "out_of_workspace", "position_error", "orientation_error")


_PLANAR = np.array([1.0, 1.0, 0.0])  # the keypoints ignore the object's height


def keypoints_at(corners, p, R) -> np.ndarray:
    """The bounding-box keypoints of an object at (p, R), height dropped (8, 3)."""
    return corners @ R.T + p * _PLANAR


def keypoint_potential_to(goal_points, corners, p, R, k1, k2) -> float:
    """The object potential at (p, R) towards precomputed goal keypoints (keypoints_at)."""
    d = keypoints_at(corners, p, R) - goal_points
    return float(k1 * np.mean(0.995 ** (k2 * np.sqrt(np.einsum("ij,ij->i", d, d)))))


def keypoint_potential(corners, p, R, p_goal, R_goal, k1, k2) -> float:
    return keypoint_potential_to(keypoints_at(corners, p_goal, R_goal), corners, p, R, k1, k2)


def pose_errors(p, R, p_goal, R_goal) -> tuple[float, float]:
    """(planar xy distance, rotation angle) between the object and its goal."""
    return math.hypot(p_goal[0] - p[0], p_goal[1] - p[1]), rotation_angle(R_goal @ R.T)


def within_tolerance(cfg, position_error: float, orientation_error: float) -> bool:
    """The task's success rule on pose_errors' two errors: `cfg` has success_position,
    check_orientation and success_orientation (a TaskConfig, or rl/primitive/hindsight's HindsightRule)."""
    return position_error <= cfg.success_position and (
        not cfg.check_orientation or orientation_error <= cfg.success_orientation)


# The previous policy step, held as one vector: [object_state, hand_state, energy].
PREVIOUS_PARTS = (FREE_BODY_STATE_DIM, HAND_STATE_DIM, 1)
PREVIOUS_SIZE = sum(PREVIOUS_PARTS)
# Where each part starts in it: computed once, not on every reward evaluation.
_PREVIOUS_SPLITS = tuple(int(i) for i in np.cumsum(PREVIOUS_PARTS)[:-1])


def split_previous(held: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(object_state, hand_state, energy) of the held previous-step vector."""
    object_state, hand_state, energy = np.split(held, _PREVIOUS_SPLITS)
    return object_state, hand_state, float(energy[0])


class TaskReward(LeafSystem):
    def __init__(self, cfg: TaskConfig, physics_steps_per_policy_step: int = 8):
        super().__init__()
        self._cfg = cfg
        self._substeps = physics_steps_per_policy_step
        self._object_state = self.DeclareVectorInputPort("object_state", FREE_BODY_STATE_DIM)
        self._hand_state = self.DeclareVectorInputPort("hand_state", HAND_STATE_DIM)
        self._goal_pose = self.DeclareVectorInputPort("goal_pose", POSE7_DIM)
        self._keypoints = self.DeclareVectorInputPort("object_keypoints", KEYPOINTS_DIM)
        self._energy = self.DeclareVectorInputPort("energy", 1)
        self._previous = self.DeclareVectorInputPort("previous", PREVIOUS_SIZE)
        self.DeclareVectorOutputPort("reward", 1, self._calc_reward)
        self._status_port = self.DeclareVectorOutputPort("task_status", len(STATUS_FIELDS),
                                                         self._calc_status)

    def _goal(self, context):
        g = self._goal_pose.Eval(context)
        return g[POSE7_POSITION], quat_wxyz_to_matrix(g[POSE7_QUATERNION])

    def _potentials(self, corners, goal_points, object_state, tool_position) -> tuple[float, float]:
        cfg = self._cfg
        p, R = free_body_pose(object_state)
        phi_obj = keypoint_potential_to(goal_points, corners, p, R, cfg.keypoint_k1,
                                        cfg.keypoint_k2)
        d = tool_position - p
        phi_hand = cfg.hand_k1 * 0.995 ** (cfg.keypoint_k2 * math.sqrt(float(d @ d)))
        return phi_obj, phi_hand

    def status(self, context) -> np.ndarray:
        cfg = self._cfg
        p, R = free_body_pose(self._object_state.Eval(context))
        p_goal, R_goal = self._goal(context)
        pos_err, ori_err = pose_errors(p, R, p_goal, R_goal)
        success = within_tolerance(cfg, pos_err, ori_err)
        out = bool(np.any(p < cfg.workspace_low) or np.any(p >= cfg.workspace_high))
        return np.array([float(success), float(out), pos_err, ori_err])

    def _calc_reward(self, context, output: BasicVector):
        cfg = self._cfg
        prev_object, prev_hand_state, prev_energy = split_previous(self._previous.Eval(context))
        # The goal's keypoints once for both potentials.
        corners = self._keypoints.Eval(context).reshape(-1, POSITION_DIM)
        goal_points = keypoints_at(corners, *self._goal(context))
        prev_obj, prev_hand = self._potentials(corners, goal_points, prev_object,
                                               prev_hand_state[POSE9_POSITION])
        phi_obj, phi_hand = self._potentials(corners, goal_points, self._object_state.Eval(context),
                                             self._hand_state.Eval(context)[POSE9_POSITION])
        success = self._status_port.Eval(context)[0] > 0  # cached: computed once per state
        obj_term = cfg.success_reward if success else cfg.potential_gamma * phi_obj - prev_obj
        hand_term = min(max(cfg.potential_gamma * phi_hand - prev_hand, -cfg.hand_clip),
                        cfg.hand_clip)
        energy = (self._energy.Eval(context)[0] - prev_energy) / self._substeps
        output.SetFromVector([obj_term + hand_term - cfg.energy_coef * energy])

    def _calc_status(self, context, output: BasicVector):
        output.SetFromVector(self.status(context))


def add_task_reward(builder: DiagramBuilder, cfg: TaskConfig, clock: PolicyClock, object_state: OutputPort, hand_state: OutputPort, energy: OutputPort,
                    name: str = "task") -> tuple[TaskReward, ZeroOrderHold]:
    """TaskReward plus the hold of the previous policy step's state; returns (reward, hold).

    Connect goal_pose and object_keypoints yourself. After writing an episode's initial state
    into a context, call `reset_previous(hold, reward, context)` so the first step's reward
    starts from it.
    """
    reward = builder.AddNamedSystem(name, TaskReward(cfg, clock.substeps))
    mux = builder.AddNamedSystem(f"{name}.previous_inputs", Multiplexer(list(PREVIOUS_PARTS)))
    hold = builder.AddNamedSystem(f"{name}.previous", ZeroOrderHold(clock.period, PREVIOUS_SIZE,
                                                                   clock.offset))
    for i, port in enumerate((object_state, hand_state, energy)):
        builder.Connect(port, mux.get_input_port(i))
    builder.Connect(object_state, reward.GetInputPort("object_state"))
    builder.Connect(hand_state, reward.GetInputPort("hand_state"))
    builder.Connect(energy, reward.GetInputPort("energy"))
    builder.Connect(mux.get_output_port(), hold.get_input_port())
    builder.Connect(hold.get_output_port(), reward.GetInputPort("previous"))
    return reward, hold


def reset_previous(hold: ZeroOrderHold, reward: TaskReward, root_context) -> None:
    """Sets the hold to the current [object_state, hand_state, energy] of `root_context`."""
    ctx = reward.GetMyContextFromRoot(root_context)
    current = np.concatenate([reward.GetInputPort(port).Eval(ctx)
                              for port in ("object_state", "hand_state", "energy")])
    hold.GetMyMutableContextFromRoot(root_context).SetDiscreteState(current)
