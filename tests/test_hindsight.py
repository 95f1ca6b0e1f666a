"""Hindsight goals for the primitive learner (rl/hindsight.py, nn/primitive_features.with_goal):
features rewritten for another goal equal the features of an observation with that goal; the
relabelled reward of the episode's own goal is PrimitiveEnv's reward (an independent
computation: the env's from the plant's pose and the object's corners); a finished episode's
copies end with its reached poses as successes; a run stores them without counting them."""

import numpy as np
import pytest
import torch

from corn_drake.config.diagram_files import load_primitive_env_config
from corn_drake.config.primitive import PrimitiveConfig, PrimitiveTrainConfig
from corn_drake.errors import InputError
from corn_drake.nn.primitive_features import location_features, with_goal
from corn_drake.package_data import data_dir
from corn_drake.rl.hindsight import (Achieved, HindsightRule, achieved_states, relative_goal,
                                     reward)
from corn_drake.rl.pretrained_encoders import load_encoder
from corn_drake.rl.primitive_env import PrimitiveEnv
from corn_drake.transforms import pose9

ENCODER = data_dir("models") / "weights" / "push_corn" / "encoder.pt"


def _rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q * np.linalg.det(q)


@pytest.mark.parametrize("locations", ["patch", "point"])
def test_features_with_another_goal_equal_the_features_of_that_goal(locations):
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
        have, _ = location_features(encoder, first, locations)
        want, _ = location_features(encoder, second, locations)
    have = {k: v.numpy() for k, v in have.items()}
    rewritten = with_goal(have, np.stack([p for p, _ in goals[B:]]),
                          np.stack([R for _, R in goals[B:]]))
    for key in want:
        np.testing.assert_allclose(rewritten[key], want[key].numpy(), atol=2e-5, err_msg=key)
    # The goal does change the features: the flow and the goal context differ from the first's.
    assert not np.allclose(rewritten["local"], have["local"], atol=1e-3)
    np.testing.assert_array_equal(rewritten["tokens"], have["tokens"])


def _own_goal(obs) -> Achieved:
    """The episode's own goal as an Achieved state, from one observation (unbatched)."""
    p = np.asarray(obs["object_position"], float)
    state = achieved_states({k: obs[k][None] for k in
                             ("object_position", "goal", "object_keypoints")})[0]
    p_goal = p + np.asarray(obs["goal"][:3], float)
    corners = (np.asarray(obs["object_keypoints"], float).reshape(-1, 3) - p) \
        @ state.goal_rotation.T  # the corners turned as the goal turns them
    corners[:, :2] += p_goal[:2]
    return Achieved(p_goal, np.eye(3), corners)


def _turning_push(env, obs) -> dict:
    """An off-centre push on a side point of the box: it moves and turns it."""
    index = int(np.argmax(np.abs(obs["normals"][:, 0]) - np.abs(obs["normals"][:, 2])
                          - 3 * np.abs(obs["cloud"][:, 2] - obs["cloud"][:, 2].mean())))
    normal = obs["normals"][index]
    inward = -np.array([normal[0], normal[1], 0.0]) / np.linalg.norm(normal[:2])
    return {"point": index, "motion": 0.6 * inward + 0.6 * np.array([-normal[1], normal[0], 0])}


def test_the_relabelled_reward_of_the_own_goal_is_the_envs_reward():
    primitive = PrimitiveConfig(turn_reward=2.0)
    env = PrimitiveEnv(load_primitive_env_config("push_turn"), primitive)
    rule = HindsightRule.for_run(1, primitive, env.cfg.task)
    obs, _ = env.reset(seed=2)
    rotation_before = env.rotation_to_goal()
    nxt, env_reward, terminated, _, info = env.step(_turning_push(env, obs))
    assert not terminated and info["status"]["success"] == 0
    assert abs(env.rotation_to_goal() - rotation_before) > 0.01  # it did turn
    [before], [after] = (achieved_states({k: o[k][None] for k in
                                          ("object_position", "goal", "object_keypoints")})
                         for o in (obs, nxt))
    goal = _own_goal(obs)
    np.testing.assert_allclose(_own_goal(nxt).keypoints, goal.keypoints, atol=1e-5)
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
            before.keypoints - after.keypoints, axis=1).mean()) + rule.turn_reward * float(
            np.arccos(np.clip((np.trace(after.goal_rotation.T @ before.goal_rotation) - 1) / 2,
                              -1, 1))), abs=1e-6)


def _cfg(**changes) -> PrimitiveTrainConfig:
    cfg = PrimitiveTrainConfig(env=load_primitive_env_config("push_turn"), envs_per_worker=2,
                               total_steps=4, random_steps=0, learning_starts=2, log_every=2,
                               checkpoint_every=100, hindsight_goals=3,
                               primitive=PrimitiveConfig(max_primitives=2))
    for key, value in changes.items():
        setattr(cfg, key, value)
    return cfg


def test_a_finished_episode_comes_back_with_its_reached_poses_as_goals(tmp_path):
    from corn_drake.rl.primitive_collection import Exploration
    from corn_drake.rl.primitive_trainer import PrimitiveTrainer

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
    from corn_drake.rl.primitive_trainer import PrimitiveTrainer

    trainer = PrimitiveTrainer(_cfg(), tmp_path, load_encoder("corn", ENCODER))
    metrics = trainer.train(progress=False)
    assert metrics["global_step"] == 4 and metrics["episodes"] == 2
    assert len(trainer.replay) == 4 * (1 + 3)  # 4 primitives, each stored with 3 goals more
    # One update per primitive collected (both rounds: the replay held 2 after the first);
    # the copies bring no updates of their own.
    assert trainer.learner.updates == 4


def test_hindsight_goals_refuse_the_tipping_penalty():
    with pytest.raises(InputError, match="hindsight_goals.*tip_penalty"):
        _cfg(primitive=PrimitiveConfig(tip_penalty=1.0)).check()
