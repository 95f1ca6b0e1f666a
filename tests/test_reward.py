"""TaskReward on hand-made states: potentials, success bonus, energy penalty, workspace flag."""

import numpy as np
import pytest

from corn_drake.config.task import TaskConfig
from corn_drake.contract import ACTION_DIM
from corn_drake.systems.reward import TaskReward, keypoint_potential
from corn_drake.transforms import yaw_matrix

CORNERS = np.array([[sx, sy, sz] for sx in (-.05, .05) for sy in (-.04, .04) for sz in (-.03, .03)])
IDENTITY_Q = np.array([1.0, 0, 0, 0])


def _state(p, yaw=0.0):
    return np.concatenate([[np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)], p, np.zeros(6)])


def _context(reward, obj, goal, tool, energy, previous=None):
    ctx = reward.CreateDefaultContext()
    if previous is None:
        previous = np.concatenate([obj, tool, np.zeros(6), [energy]])
    reward.GetInputPort("previous").FixValue(ctx, previous)
    reward.GetInputPort("object_state").FixValue(ctx, obj)
    reward.GetInputPort("hand_state").FixValue(ctx, np.concatenate([tool, np.zeros(6)]))
    reward.GetInputPort("goal_pose").FixValue(ctx, goal)
    reward.GetInputPort("object_keypoints").FixValue(ctx, CORNERS.reshape(-1))
    reward.GetInputPort("energy").FixValue(ctx, [energy])
    return ctx


def test_success_and_errors_at_and_near_the_goal():
    cfg = TaskConfig()
    r = TaskReward(cfg, 8)
    goal = np.concatenate([[0.1, 0.0, 0.45], IDENTITY_Q])
    at_goal = _context(r, _state([0.13, 0.02, 0.45], yaw=0.05), goal, [0, 0, 0.6], 0.0)
    status = r.GetOutputPort("task_status").Eval(at_goal)
    assert status[0] == 1.0 and status[1] == 0.0
    assert status[2] == pytest.approx(np.hypot(0.03, 0.02))
    assert status[3] == pytest.approx(0.05)
    # z does not count for position (planar), rotation does.
    off_z = _context(r, _state([0.1, 0.0, 0.6]), goal, [0, 0, 0.6], 0.0)
    assert r.GetOutputPort("task_status").Eval(off_z)[0] == 1.0
    rotated = _context(r, _state([0.1, 0.0, 0.45], yaw=0.2), goal, [0, 0, 0.6], 0.0)
    assert r.GetOutputPort("task_status").Eval(rotated)[0] == 0.0
    out = _context(r, _state([0.6, 0.0, 0.45]), goal, [0, 0, 0.6], 0.0)
    assert r.GetOutputPort("task_status").Eval(out)[1] == 1.0



def test_success_ignores_the_orientation_only_when_the_task_says_so():
    goal = np.concatenate([[0.1, 0.0, 0.45], IDENTITY_Q])
    turned = _state([0.12, 0.0, 0.45], yaw=2.5)  # within 5 cm, turned far past 0.1 rad
    checked = TaskReward(TaskConfig(), 8)
    assert checked.GetOutputPort("task_status").Eval(
        _context(checked, turned, goal, [0, 0, 0.6], 0.0))[0] == 0.0
    position_only = TaskReward(TaskConfig(check_orientation=False), 8)
    status = position_only.GetOutputPort("task_status").Eval(
        _context(position_only, turned, goal, [0, 0, 0.6], 0.0))
    assert status[0] == 1.0 and status[3] == pytest.approx(2.5)  # the error is still reported
    too_far = _context(position_only, _state([0.2, 0.0, 0.45]), goal, [0, 0, 0.6], 0.0)
    assert position_only.GetOutputPort("task_status").Eval(too_far)[0] == 0.0

def test_reward_is_potential_difference_plus_success_bonus_minus_energy():
    cfg = TaskConfig()
    r = TaskReward(cfg, 8)
    goal = np.concatenate([[0.1, 0.0, 0.45], IDENTITY_Q])
    tool = np.array([0.0, 0.0, 0.5])
    # The held previous step: object at x = -0.05, 10 J spent so far.
    ctx = _context(r, _state([-0.05, 0.0, 0.45]), goal, tool, energy=10.0)
    prev_obj = keypoint_potential(CORNERS, np.array([-0.05, 0, 0.45]), np.eye(3),
                                  goal[:3], np.eye(3), cfg.keypoint_k1, cfg.keypoint_k2)
    # Move the object halfway to the goal and spend 50 J.
    r.GetInputPort("object_state").FixValue(ctx, _state([0.02, 0.0, 0.45]))
    r.GetInputPort("energy").FixValue(ctx, [60.0])
    new_obj = keypoint_potential(CORNERS, np.array([0.02, 0, 0.45]), np.eye(3), goal[:3],
                                 np.eye(3), cfg.keypoint_k1, cfg.keypoint_k2)
    hand_prev = cfg.hand_k1 * 0.995 ** (cfg.keypoint_k2 * np.linalg.norm(tool - [-0.05, 0, 0.45]))
    hand_new = cfg.hand_k1 * 0.995 ** (cfg.keypoint_k2 * np.linalg.norm(tool - [0.02, 0, 0.45]))
    # Energy: 50 over the step's 8 physics steps -> a mean of 6.25 per physics step.
    expected = (0.995 * new_obj - prev_obj) + (0.995 * hand_new - hand_prev) - 1e-4 * 50.0 / 8
    assert new_obj > prev_obj
    assert r.GetOutputPort("reward").Eval(ctx)[0] == pytest.approx(expected)
    # At the goal the object term becomes the +1 success bonus.
    r.GetInputPort("object_state").FixValue(ctx, _state([0.1, 0.0, 0.45]))
    hand_goal = cfg.hand_k1 * 0.995 ** (cfg.keypoint_k2 * np.linalg.norm(tool - [0.1, 0, 0.45]))
    expected = 1.0 + (0.995 * hand_goal - hand_prev) - 1e-4 * 50.0 / 8
    assert r.GetOutputPort("reward").Eval(ctx)[0] == pytest.approx(expected)


def test_keypoint_potential_sees_rotation_but_not_height():
    args = (CORNERS, np.array([0, 0, 0.5]), np.eye(3), np.array([0, 0, 0.45]))
    same = keypoint_potential(*args, np.eye(3), 0.302, 243.12)
    assert same == pytest.approx(0.302)
    assert keypoint_potential(*args, yaw_matrix(0.5), 0.302, 243.12) < same


def test_hold_in_the_teacher_diagram_latches_the_previous_policy_step():
    from corn_drake.rl.envs.teacher_env import TeacherEnv

    env = TeacherEnv()
    env.reset(seed=0)
    from corn_drake.systems.reward import split_previous

    hold_port = env.handles.reward.GetInputPort("previous")

    def held_object_state():
        return split_previous(hold_port.Eval(reward_ctx))[0]

    reward_ctx = env.handles.reward.GetMyContextFromRoot(env.context)
    object_port = env.diagram.GetOutputPort("plant.object_state")
    before = object_port.Eval(env.context).copy()
    np.testing.assert_allclose(held_object_state(), before)
    env.step(np.zeros(20))
    # After one policy step the hold still shows the state at the start of that step...
    np.testing.assert_allclose(held_object_state(), before, atol=1e-12)
    mid = object_port.Eval(env.context).copy()
    env.step(np.zeros(20))
    # ...and after the next, the state at the start of the next one.
    np.testing.assert_allclose(held_object_state(), mid, atol=1e-12)
    assert split_previous(hold_port.Eval(reward_ctx))[2] > 0  # energy accumulates while the arm moves


def test_energy_meter_is_built_only_when_the_task_pays_for_energy():
    """With energy_coef 0 the diagram has no meter (it would run every physics step for a term
    multiplied by zero), and the reward is the same as with a meter and coefficient 0."""
    from corn_drake.builders.teacher import build_teacher_diagram
    from corn_drake.config.plumbing.diagram_files import load_teacher_config
    from corn_drake.rl.envs.teacher_env import TeacherEnv

    def names(cfg):
        return {s.get_name() for s in build_teacher_diagram(cfg).diagram.GetSystems()}

    paid = load_teacher_config()
    assert paid.task.energy_coef > 0 and "energy_meter" in names(paid)
    free = load_teacher_config("push")
    assert free.task.energy_coef == 0 and "energy_meter" not in names(free)

    rewards = []
    for coef in (0.0, 1e-30):  # 1e-30: the meter is built, its term is nothing
        cfg = load_teacher_config("push")
        cfg.task.energy_coef = coef
        env = TeacherEnv(cfg)
        env.reset(seed=4)
        rng = np.random.default_rng(0)
        rewards.append([env.step(rng.uniform(-1, 1, ACTION_DIM))[1] for _ in range(5)])
    np.testing.assert_allclose(rewards[0], rewards[1], rtol=0, atol=1e-12)
