"""Hindsight goals for the primitive learner (rl/primitive/hindsight.py, nn/primitive_features.with_goal):
features rewritten for another goal equal the features of an observation with that goal; the
relabelled reward of the episode's own goal is PrimitiveEnv's reward (an independent
computation: the env's from the plant's pose and the object's corners); a finished episode's
copies end with its reached poses as successes, the pose it left the workspace at included; a
run stores them without counting them."""

import numpy as np
import pytest
import torch

from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
from corn_drake.config.primitive import PrimitiveConfig, PrimitiveTrainConfig
from corn_drake.nn.primitive_features import location_features, with_goal
from corn_drake.package_data import data_dir
from corn_drake.rl.primitive.hindsight import (Achieved, HindsightEpisodes, HindsightRule,
                                               achieved_states, relative_goal, reward, rotation_to,
                                               succeeded)
from corn_drake.rl.pretrained_encoders import load_encoder
from corn_drake.rl.envs.primitive_env import PrimitiveEnv
from corn_drake.transforms import pose9

ENCODER = data_dir("models") / "weights" / "push_corn" / "encoder.pt"


def _rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q * np.linalg.det(q)


def test_features_with_another_goal_equal_the_features_of_that_goal():
    rng = np.random.default_rng(0)
    encoder = load_encoder("corn", ENCODER)
    B, N = 2, 512

    def obs(goals):
        normals = rng.normal(size=(B, N, 3))
        return {"cloud": torch.tensor(rng.normal(0.0, 0.04, (B, N, 3)) + [0.0, 0.0, 0.45]),
                "hand_state": torch.tensor(np.stack([pose9(rng.normal(0, 0.1, 3), _rotation(rng))
                                                     for _ in range(B)])),
                "object_position": torch.tensor(rng.normal(0.0, 0.05, (B, 3))),
                "normals": torch.tensor(normals / np.linalg.norm(normals, axis=-1,
                                                                 keepdims=True)),
                "goal": torch.tensor(np.stack(goals))}

    goals = [(rng.normal(0, 0.1, 3), _rotation(rng)) for _ in range(2 * B)]
    first = obs([pose9(p, R) for p, R in goals[:B]])
    second = dict(first, goal=torch.tensor(np.stack([pose9(p, R) for p, R in goals[B:]])))
    first = {k: v.float() for k, v in first.items()}
    second = {k: v.float() for k, v in second.items()}
    with torch.no_grad():
        have, _ = location_features(encoder, first)
        want, _ = location_features(encoder, second)
    have = {k: v.numpy() for k, v in have.items()}
    rewritten = with_goal(have, np.stack([p for p, _ in goals[B:]]),
                          np.stack([R for _, R in goals[B:]]))
    for key in want:
        np.testing.assert_allclose(rewritten[key], want[key].numpy(), atol=2e-5, err_msg=key)
    # The goal does change the features: the flow and the goal context differ from the first's.
    assert not np.allclose(rewritten["local"], have["local"], atol=1e-3)
    np.testing.assert_array_equal(rewritten["tokens"], have["tokens"])


KEYS = ("object_position", "goal", "object_keypoints")


def _own_goal(obs) -> Achieved:
    """The episode's own goal as an Achieved state, from one observation (unbatched)."""
    p = np.asarray(obs["object_position"], float)
    state = achieved_states({k: obs[k][None] for k in KEYS})[0]
    p_goal = p + np.asarray(obs["goal"][:3], float)
    points = (np.asarray(obs["object_keypoints"], float).reshape(-1, 3) - p) \
        @ state.goal_rotation.T  # the points turned as the goal turns them
    points[:, :2] += p_goal[:2]
    return Achieved(p_goal, np.eye(3), points)


def _turning_push(env, obs) -> dict:
    """An off-centre push on a side point of the box: it moves and turns it."""
    index = int(np.argmax(np.abs(obs["normals"][:, 0]) - np.abs(obs["normals"][:, 2])
                          - 3 * np.abs(obs["cloud"][:, 2] - obs["cloud"][:, 2].mean())))
    normal = obs["normals"][index]
    inward = -np.array([normal[0], normal[1], 0.0]) / np.linalg.norm(normal[:2])
    return {"point": index, "motion": 0.6 * inward + 0.6 * np.array([-normal[1], normal[0], 0])}


def test_the_relabelled_reward_of_the_own_goal_is_the_envs_reward():
    # A push at the contact point's own height, vertical fingers: _turning_push then turns the
    # box (a low push with leaning fingers slides it), so the relabelled rotation is tested too.
    primitive = PrimitiveConfig(push_height=0.0, finger_tilt_deg=0.0)
    env = PrimitiveEnv(load_primitive_env_config("push_turn"), primitive)
    rule = HindsightRule.for_run(1, primitive, env.cfg.task)
    obs, _ = env.reset(seed=2)
    nxt, env_reward, terminated, _, info = env.step(_turning_push(env, obs))
    assert not terminated and info["status"]["success"] == 0
    [before], [after] = (achieved_states({k: o[k][None] for k in KEYS}) for o in (obs, nxt))
    goal = _own_goal(obs)
    assert abs(rotation_to(after, goal) - rotation_to(before, goal)) > 0.01  # it did turn
    np.testing.assert_allclose(_own_goal(nxt).points, goal.points, atol=1e-5)
    # The goal relative to each state, as its observation holds it.
    for state, o in ((before, obs), (after, nxt)):
        position, rotation = relative_goal(state, goal)
        np.testing.assert_allclose(pose9(position, rotation), o["goal"], atol=1e-5)
    assert reward(rule, before, after, goal) == pytest.approx(env_reward, abs=1e-4)
    # The pose it reached, as the goal: a success, worth the task's success reward on top of
    # the progress toward it.
    reached = reward(rule, before, after, after)
    assert reached > env.cfg.task.success_reward
    assert reached == pytest.approx(
        rule.success_reward + rule.progress_reward * float(np.linalg.norm(
            before.points - after.points, axis=1).mean()), abs=1e-6)


def _cfg(**changes) -> PrimitiveTrainConfig:
    cfg = PrimitiveTrainConfig(env=load_primitive_env_config("push_turn"), envs_per_worker=2,
                               total_steps=4, random_steps=0, learning_starts=2, log_every=2,
                               checkpoint_every=100, hindsight_goals=3,
                               primitive=PrimitiveConfig(max_primitives=2))
    for key, value in changes.items():
        setattr(cfg, key, value)
    return cfg


def test_a_finished_episode_comes_back_with_its_reached_poses_as_goals(tmp_path):
    from corn_drake.rl.primitive.collection import Exploration
    from corn_drake.rl.training.primitive_trainer import PrimitiveTrainer

    trainer = PrimitiveTrainer(_cfg(), tmp_path, load_encoder("corn", ENCODER))
    explore = Exploration(random=True, temperature=0.1, motion_noise=0.3)
    first = trainer.collector.collect(1, explore, trainer.np_rng)
    second = trainer.collector.collect(1, explore, trainer.np_rng)
    # Both envs' episodes ran their 2-primitive budget and ended in the second round.
    assert first.relabeled is None and not first.episode_stats
    assert [s["length"] for s in second.episode_stats] == [2, 2]
    copies = second.relabeled
    assert len(copies) == 2 * 2 * 3  # 2 episodes x 2 transitions x 3 goals, env after env
    task_success = trainer.cfg.env.task.success_reward
    for env in range(2):
        block = 6 * env
        # Transition t's copies (t-major) keep its state's tokens and the choice made in it.
        for t, transitions in enumerate((first, second)):
            rows = slice(block + 3 * t, block + 3 * t + 3)
            np.testing.assert_array_equal(copies.features["tokens"][rows],
                                          np.repeat(transitions.features["tokens"][env:env + 1],
                                                    3, axis=0))
            assert (copies.locations[rows] == transitions.locations[env]).all()
        # The last transition can only take the pose it led to as its goal: a success, which
        # ends the copy, with no flow left and the identity as the goal's relative pose.
        last = slice(block + 3, block + 6)
        assert copies.terminated[last].all()
        assert (copies.rewards[last] >= task_success - 1e-6).all()
        np.testing.assert_allclose(copies.next_features["local"][last][..., 3:6], 0, atol=1e-4)
        np.testing.assert_allclose(copies.next_features["global"][last][:, :9],
                                   np.tile([0, 0, 0, 1, 0, 0, 0, 1, 0], (3, 1)), atol=1e-4)
    # The episodes' own transitions did not succeed: the copies are what carries a success.
    assert not second.terminated.any()


def test_a_hindsight_run_stores_the_copies_and_counts_only_its_primitives(tmp_path):
    from corn_drake.rl.training.primitive_trainer import PrimitiveTrainer

    trainer = PrimitiveTrainer(_cfg(), tmp_path, load_encoder("corn", ENCODER))
    metrics = trainer.train(progress=False)
    assert metrics["global_step"] == 4 and metrics["episodes"] == 2
    assert len(trainer.replay) == 4 * (1 + 3)  # 4 primitives, each stored with 3 goals more
    # One update per primitive collected (both rounds: the replay held 2 after the first);
    # the copies bring no updates of their own.
    assert trainer.learner.updates == 4


def test_an_at_rest_runs_collector_relabels_with_the_final_speeds(tmp_path):
    """The collector hands the ended episodes' final speeds to the relabelling: a run with
    success_at_rest and hindsight goals collects, and the copies of each episode's last push
    (whose only goal is the pose it led to) are one copy three times: all of them succeed or
    none, as that push's one final speed decides (a missing speed would be refused)."""
    from corn_drake.rl.primitive.collection import Exploration
    from corn_drake.rl.training.primitive_trainer import PrimitiveTrainer

    cfg = _cfg(primitive=PrimitiveConfig(max_primitives=2, success_at_rest=True))
    trainer = PrimitiveTrainer(cfg, tmp_path, load_encoder("corn", ENCODER))
    assert trainer.collector.hindsight.rule.at_rest
    explore = Exploration(random=True, temperature=0.1, motion_noise=0.3)
    trainer.collector.collect(1, explore, trainer.np_rng)
    copies = trainer.collector.collect(1, explore, trainer.np_rng).relabeled
    assert len(copies.rewards) == 2 * 2 * 3
    for env in range(2):
        last = slice(6 * env + 3, 6 * env + 6)
        done = copies.terminated[last]
        assert done.all() or not done.any()
        np.testing.assert_allclose(copies.rewards[last], copies.rewards[last][0], atol=1e-6)


def test_at_rest_a_relabelled_success_needs_the_object_still():
    """With success_at_rest the run's rule asks the object's speed at the primitive's end, as
    the env does: the same pose reached while sliding is no success, reached still it is; a
    state whose observation had no speed is refused rather than guessed."""
    _cfg(primitive=PrimitiveConfig(success_at_rest=True)).check()  # no longer refused
    task = _cfg().env.task
    rule = HindsightRule.for_run(4, PrimitiveConfig(success_at_rest=True), task)
    pose_rule = HindsightRule.for_run(4, PrimitiveConfig(), task)
    assert rule.at_rest and not pose_rule.at_rest
    corners = np.array([[x, y, z] for x in (-0.05, 0.05) for y in (-0.03, 0.03)
                        for z in (0.0, 0.04)])

    def state(x: float, speed) -> Achieved:
        return Achieved(np.array([x, 0.0, 0.42]), np.eye(3), corners + [x, 0.0, 0.0],
                        None if speed is None else np.array(speed))

    goal = state(0.10, (0.0, 0.0))
    sliding, still = state(0.10, (0.30, 0.0)), state(0.10, (0.001, 0.01))
    spinning = state(0.10, (0.0, 3.0))
    assert succeeded(pose_rule, sliding, goal) and succeeded(rule, still, goal)
    assert not succeeded(rule, sliding, goal) and not succeeded(rule, spinning, goal)
    before = state(0.0, (0.0, 0.0))
    assert reward(rule, before, still, goal) - reward(rule, before, sliding, goal) == \
        pytest.approx(task.success_reward)
    with pytest.raises(ValueError, match="object_speed"):
        succeeded(rule, state(0.10, None), goal)
    assert not succeeded(rule, state(0.30, None), goal)  # out of tolerance: no speed needed


def test_the_env_observes_the_speed_hindsight_judges_rest_by(tmp_path):
    """object_speed in the primitive env's observation is the env's own object_speed(), and
    achieved_states carries it."""
    env = PrimitiveEnv(load_primitive_env_config("push"), PrimitiveConfig(max_primitives=1))
    obs, _ = env.reset(seed=3)
    index = int(np.argmax(np.abs(obs["normals"][:, 0]) - np.abs(obs["normals"][:, 2])))
    obs, *_ = env.step({"point": index, "motion": -obs["normals"][index]})
    speed = env.object_speed()
    np.testing.assert_allclose(obs["object_speed"], [speed["linear"], speed["angular"]],
                               rtol=1e-6)
    assert env.observation_space["object_speed"].contains(obs["object_speed"])
    state = achieved_states({k: obs[k][None] for k in ("object_position", "goal",
                                                       "object_speed", "object_keypoints")})[0]
    np.testing.assert_allclose(state.speed, obs["object_speed"])


def _episode_leaving_the_workspace() -> dict:
    """The copies of a hand-made 3-primitive episode whose last push threw the object 0.6 m
    away (the env ended it there without success)."""
    rule = HindsightRule(goals=8, progress_reward=10.0, success_reward=1.0,
                         success_position=0.05, success_orientation=0.25,
                         check_orientation=True)
    corners = np.array([[x, y, z] for x in (-0.05, 0.05) for y in (-0.03, 0.03)
                        for z in (0.0, 0.04)])

    def state(x: float) -> Achieved:
        return Achieved(np.array([x, 0.0, 0.42]), np.eye(3), corners + [x, 0.0, 0.0])

    episodes = HindsightEpisodes(rule, 1)
    episodes.begin(0, state(0.0))
    for t, x in enumerate((0.04, 0.08, 0.68)):
        features = {"tokens": np.full((16, 4), t, np.float32),
                    "local": np.zeros((16, 9), np.float32),
                    "global": np.zeros(146, np.float32)}
        episodes.add(0, features, t, np.zeros(3), t == 2, features, state(x))
    return episodes.finish(0, succeeded_=False, relabel=True, rng=np.random.default_rng(0))


def test_a_pose_outside_the_workspace_is_a_goal_too():
    copies = _episode_leaving_the_workspace()
    # Every copy of the push that threw the object out takes that pose: a success each time,
    # and the end of the copy (the env ended the episode there).
    thrown = copies["locations"] == 2
    assert thrown.sum() == 8 and (copies["rewards"][thrown] > 1.0).all()
    assert copies["terminated"][thrown].all()
    # The earlier pushes' copies may take it too (0.6 m ahead of them).
    assert (copies["features"]["global"][:, 0] / 10.0).max() > 0.5
    assert len(copies["locations"]) == 3 * 8
