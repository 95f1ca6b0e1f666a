"""The env's snapshot and restore, and the one-step lookahead built on them: a primitive replayed
from a snapshot ends exactly where it ended the first time, whatever was tried in between; a
snapshot only goes back into its own env; the lookahead keeps the candidate with the most reward,
leaves the env where that candidate left it, and lets the policy's own choice win a tie."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
from corn_drake.config.primitive import PrimitiveConfig
from corn_drake.errors import InputError
from corn_drake.rl.primitive.outcome.lookahead import candidate_primitives, lookahead_step
from corn_drake.rl.envs.primitive_env import PrimitiveEnv


# Pushes at the chosen point's own height with vertical fingers: _side_push then slides the
# box 9 cm (the shipped low push with leaning fingers hardly moves it from this side point).
AT_THE_POINT = {"push_height": 0.0, "finger_tilt_deg": 0.0}


def _env() -> PrimitiveEnv:
    return PrimitiveEnv(load_primitive_env_config("push"), PrimitiveConfig(**AT_THE_POINT))


def _side_push(obs: dict, scale: float = 0.5) -> dict:
    """A horizontal push into the box at its side point most nearly facing -x."""
    normals = obs["normals"]
    point = int(np.argmin(normals[:, 0] + 10 * np.abs(normals[:, 2])))
    return {"point": point, "motion": scale * np.array([1.0, 0.0, 0.0])}


def _miss(obs: dict) -> dict:
    """A primitive that pulls away from the box: the box does not move."""
    push = _side_push(obs)
    return {"point": push["point"], "motion": -push["motion"]}


def _state(env: PrimitiveEnv):
    return (env.object_pose(), env.context.get_time(), env._steps, env.primitives,
            env.executor_status())


def test_a_primitive_replayed_from_a_snapshot_ends_where_it_did():
    env = _env()
    obs, _ = env.reset(seed=2)
    push = _side_push(obs)
    start_pose = env.object_pose()
    snapshot = env.snapshot()
    first = env.step(push)
    after_first = _state(env)
    assert np.linalg.norm(after_first[0][:3] - start_pose[:3]) > 0.01, \
        "the push did not move the box: the test would prove nothing"
    env.restore(snapshot)
    np.testing.assert_array_equal(env.object_pose(), start_pose)
    assert env._steps == 0 and env.primitives == 0
    env.step(_miss(obs))  # something else in between
    assert np.abs(env.object_pose() - after_first[0]).max() > 0.01
    env.restore(snapshot)
    np.testing.assert_array_equal(env.object_pose(), start_pose)
    again = env.step(push)
    for a, b in zip(after_first, _state(env)):
        np.testing.assert_array_equal(a, b)
    assert again[1] == first[1]  # the reward
    np.testing.assert_array_equal(again[0]["cloud"], first[0]["cloud"])


def test_a_snapshot_goes_back_only_into_its_own_env():
    env, other = _env(), _env()
    with pytest.raises(InputError, match="reset"):
        env.snapshot()
    env.reset(seed=2)
    other.reset(seed=2)
    with pytest.raises(InputError, match="not taken from this env"):
        other.restore(env.snapshot())
    with pytest.raises(InputError, match="not taken from this env"):
        env.restore("a snapshot")


def test_the_lookahead_keeps_the_best_candidate_and_its_state():
    env = _env()
    obs, _ = env.reset(seed=2)
    start = env.snapshot()
    candidates = [(0, p["point"], p["motion"]) for p in
                  (_miss(obs), _side_push(obs, 0.3), _side_push(obs, 1.0))]
    rewards, ends = [], []
    for _, point, motion in candidates:  # each candidate played on its own
        env.restore(start)
        rewards.append(env.step({"point": point, "motion": motion})[1])
        ends.append(env.object_pose())
    assert len(set(np.round(rewards, 9))) == 3, "the candidates must earn different rewards"
    env.restore(start)
    result = lookahead_step(env, candidates)
    np.testing.assert_array_equal(result.rewards, rewards)
    assert result.chosen == int(np.argmax(rewards)) and result.greedy_reward == rewards[0]
    np.testing.assert_array_equal(env.object_pose(), ends[result.chosen])
    assert env.primitives == 1
    # A tie goes to the first candidate (the policy's own choice).
    env.restore(start)
    tie = lookahead_step(env, [candidates[0], candidates[0]])
    assert tie.chosen == 0
    with pytest.raises(InputError, match="no candidate"):
        lookahead_step(env, [])


def test_the_candidates_are_the_policys_choice_its_actor_elsewhere_and_random_motions():
    rng = np.random.default_rng(0)
    locations = 6
    usable = np.array([True, True, False, True, True, False])
    motions = rng.uniform(-1, 1, (locations, 3))
    choice = {"point": 30, "motion": motions[3], "location": 3, "usable": usable,
              "candidates": np.arange(locations) * 10, "motions": motions}
    out = candidate_primitives(choice, 2, np.random.default_rng(1))
    assert len(out) == 4 + 2 * 4  # the greedy one, 3 other usable locations, 2 random each
    assert out[0][:2] == (3, 30) and np.array_equal(out[0][2], motions[3])
    assert [(l, p) for l, p, _ in out[1:4]] == [(0, 0), (1, 10), (4, 40)]  # the actor elsewhere
    for location, _, m in out[1:4]:
        np.testing.assert_array_equal(m, motions[location])
    assert [l for l, _, _ in out[4:]] == [0, 0, 1, 1, 3, 3, 4, 4]  # never 2 or 5
    assert all(np.all(np.abs(m) <= 1) for _, _, m in out[4:])
    with pytest.raises(InputError, match="random_motions"):
        candidate_primitives(choice, -1, rng)


def test_the_agents_choice_carries_every_locations_motion():
    from corn_drake.nn.encoders.encoder_files import make_policy_encoder
    from corn_drake.rl.primitive.agent import PrimitiveAgent

    torch.manual_seed(0)
    agent = PrimitiveAgent(make_policy_encoder("corn")).eval()
    env = _env()
    obs, _ = env.reset(seed=2)
    choice = agent.choose(obs)
    assert choice["motions"].shape == (len(choice["candidates"]), 3)
    np.testing.assert_allclose(choice["motions"][choice["location"]], choice["motion"])


# ------------------------------------------------------------------------- success at rest

def _push_through_goal(at_rest: bool):
    """A box's full-length push along +x, its goal set halfway along where the push ends it
    (3 cm tolerance): the box passes through the goal mid-push and comes to rest beyond it."""
    import dataclasses

    cfg = load_primitive_env_config("push")
    cfg.task.success_position = 0.03
    env = PrimitiveEnv(cfg, PrimitiveConfig(success_at_rest=at_rest, **AT_THE_POINT))
    obs, _ = env.reset(seed=2)
    start, snapshot = env.object_pose(), env.snapshot()
    push = _side_push(obs, 1.0)
    env.step(push)
    end = env.object_pose()
    moved = np.linalg.norm(end[:2] - start[:2])
    assert moved > 0.08, f"the push moved the box only {moved:.3f} m"
    env.restore(snapshot)
    goal = np.array(env.episode.goal_pose, float)
    goal[:2], goal[3:] = (start[:2] + end[:2]) / 2, start[3:]
    source = env.handles.teacher.sources["goal_pose"]
    source.get_mutable_source_value(source.GetMyMutableContextFromRoot(env.context)).set_value(
        goal)
    env.episode = dataclasses.replace(env.episode, goal_pose=goal)
    return env, push, end


def test_the_tasks_rule_counts_a_goal_the_object_passes_through():
    env, push, _ = _push_through_goal(at_rest=False)
    _, reward, terminated, _, info = env.step(push)
    assert terminated and info["status"]["success"] > 0


def test_at_rest_a_pass_through_is_no_success_and_the_primitive_ends():
    env, push, end = _push_through_goal(at_rest=True)
    _, reward, terminated, truncated, info = env.step(push)
    assert not terminated and not truncated and info["status"]["success"] == 0
    np.testing.assert_allclose(env.object_pose(), end, atol=1e-9)  # the whole push was made
    assert reward < env.cfg.task.success_reward


def test_at_rest_a_still_object_at_the_goal_is_a_success():
    env, push, end = _push_through_goal(at_rest=True)
    source = env.handles.teacher.sources["goal_pose"]
    goal = np.array(env.episode.goal_pose, float)
    goal[:3] = end[:3]
    source.get_mutable_source_value(source.GetMyMutableContextFromRoot(env.context)).set_value(
        goal)
    before = env.keypoint_distance()
    _, reward, terminated, _, info = env.step(push)
    assert terminated and info["status"]["success"] > 0 and env.object_still()
    progress = env.primitive_cfg.progress_reward * (before - env.keypoint_distance())
    assert reward == pytest.approx(progress + env.cfg.task.success_reward)


def test_at_rest_the_policy_inside_the_diagram_is_judged_by_the_same_rule():
    """The in-diagram path's verdict (evaluate's): a success with the executor busy is revoked
    and the episode goes on; idle with the object still, it stands."""
    env = PrimitiveEnv(load_primitive_env_config("push"), PrimitiveConfig(success_at_rest=True))
    env.reset(seed=2)
    assert env.object_still()
    info = {"status": {"success": 1.0, "out_of_workspace": 0.0}}
    assert env._judge_at_rest(info, idle=False) == (False, False)
    assert info["status"]["success"] == 0.0
    info = {"status": {"success": 1.0, "out_of_workspace": 0.0}}
    assert env._judge_at_rest(info, idle=True) == (True, False)
    assert info["status"]["success"] == 1.0
