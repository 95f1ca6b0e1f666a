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

import numpy as np
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem, OutputPort
from pydrake.systems.primitives import Multiplexer, ZeroOrderHold

from corn_drake.config import TaskConfig
from corn_drake.systems.observations import object_pose_from_state
from corn_drake.timing import PolicyClock
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


PREVIOUS_SIZE = 13 + 9 + 1  # held [object_state, hand_state, energy]


class TaskReward(LeafSystem):
    def __init__(self, cfg: TaskConfig, physics_steps_per_policy_step: int = 8):
        super().__init__()
        self._cfg = cfg
        self._substeps = physics_steps_per_policy_step
        self.DeclareVectorInputPort("object_state", 13)
        self.DeclareVectorInputPort("hand_state", 9)
        self.DeclareVectorInputPort("goal_pose", 7)
        self.DeclareVectorInputPort("object_keypoints", 24)
        self.DeclareVectorInputPort("energy", 1)
        self.DeclareVectorInputPort("previous", PREVIOUS_SIZE)
        self.DeclareVectorOutputPort("reward", 1, self._calc_reward)
        self._status_port = self.DeclareVectorOutputPort("task_status", len(STATUS_FIELDS),
                                                         self._calc_status)

    def _goal(self, context):
        g = self.get_input_port(2).Eval(context)
        return g[:3], quat_wxyz_to_matrix(g[3:])

    def potentials(self, context, object_state, tool_position) -> tuple[float, float]:
        cfg = self._cfg
        p, R = object_pose_from_state(object_state)
        corners = self.get_input_port(3).Eval(context).reshape(8, 3)
        phi_obj = keypoint_potential(corners, p, R, *self._goal(context), cfg.keypoint_k1,
                                     cfg.keypoint_k2)
        phi_hand = cfg.hand_k1 * 0.995 ** (cfg.keypoint_k2 * float(np.linalg.norm(tool_position - p)))
        return phi_obj, phi_hand

    def status(self, context) -> np.ndarray:
        cfg = self._cfg
        p, R = object_pose_from_state(self.get_input_port(0).Eval(context))
        p_goal, R_goal = self._goal(context)
        pos_err, ori_err = pose_errors(p, R, p_goal, R_goal)
        oriented = not cfg.check_orientation or ori_err <= cfg.success_orientation
        success = pos_err <= cfg.success_position and oriented
        out = bool(np.any(p < cfg.workspace_low) or np.any(p >= cfg.workspace_high))
        return np.array([float(success), float(out), pos_err, ori_err])

    def _calc_reward(self, context, output: BasicVector):
        cfg = self._cfg
        prev = self.get_input_port(5).Eval(context)
        prev_obj, prev_hand = self.potentials(context, prev[:13], prev[13:16])
        phi_obj, phi_hand = self.potentials(context, self.get_input_port(0).Eval(context),
                                            self.get_input_port(1).Eval(context)[:3])
        success = self._status_port.Eval(context)[0] > 0  # cached: computed once per state
        obj_term = cfg.success_reward if success else cfg.potential_gamma * phi_obj - prev_obj
        hand_term = np.clip(cfg.potential_gamma * phi_hand - prev_hand, -cfg.hand_clip, cfg.hand_clip)
        energy = (self.get_input_port(4).Eval(context)[0] - prev[-1]) / self._substeps
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
    mux = builder.AddNamedSystem(f"{name}.previous_inputs", Multiplexer([13, 9, 1]))
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
    current = np.concatenate([reward.get_input_port(i).Eval(ctx) for i in (0, 1, 4)])
    hold.GetMyMutableContextFromRoot(root_context).SetDiscreteState(current)
