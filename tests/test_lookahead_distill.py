"""Distilling the one-step lookahead: the collected states hold every candidate's reward from the
same state, an episode that follows the policy is the policy's own episode, the critic fitted to
the rewards predicts them better than before, and the actor's fit raises the critic's value."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from corn_drake.config.diagram_files import load_primitive_env_config
from corn_drake.config.primitive import PrimitiveConfig
from corn_drake.errors import InputError
from corn_drake.rl.primitive.outcome.lookahead_distill import (choice_quality, collect_episode, critic_error,
                                             fit_actor, fit_critic, scores_quality, stack_states)
from corn_drake.rl.envs.primitive_env import PrimitiveEnv


def _agent():
    from corn_drake.nn.encoder_files import make_policy_encoder
    from corn_drake.rl.primitive.agent import PrimitiveAgent

    torch.manual_seed(0)
    return PrimitiveAgent(make_policy_encoder("corn"), "patch").eval()


def _env(max_primitives: int = 2) -> PrimitiveEnv:
    return PrimitiveEnv(load_primitive_env_config("push"),
                        PrimitiveConfig(max_primitives=max_primitives))


@pytest.fixture(scope="module")
def collected():
    agent, env = _agent(), _env()
    states, outcome = collect_episode(env, agent, 3, 1, 0.0, np.random.default_rng(0))
    return agent, states, outcome


def test_each_state_holds_every_candidates_reward(collected):
    agent, states, outcome = collected
    assert outcome["primitives"] == len(states) == 2
    for state in states:
        locations = state["features"]["tokens"].shape[0]
        usable = int(state["features"]["mask"].sum())
        # The greedy one, the actor at the other usable locations, one random motion at each.
        assert len(state["reward"]) == len(state["location"]) == len(state["motion"]) \
            == 2 * usable
        assert set(state["location"]) <= set(range(locations))
        assert np.isfinite(state["reward"]).all() and np.abs(state["motion"]).max() <= 1
    assert np.ptp(states[0]["reward"]) > 0, "every candidate earned the same: nothing to learn"


def test_each_candidates_outcome_gives_back_its_reward(collected):
    """The stored outcome (the object's pose before and after each candidate, its goal and box
    keypoints) recomputes each candidate's reward independently of the env: 10 x how much the
    candidate closed the mean keypoint distance to the goal (heights of the origin dropped),
    plus the task's success reward where the candidate succeeded. A model of the primitives'
    outcomes can be fitted to these and scored by the same rule."""
    from corn_drake.transforms import quat_wxyz_to_matrix

    _, states, _ = collected
    data = stack_states(states)

    def keypoints(corners, pose):
        return corners @ quat_wxyz_to_matrix(pose[3:]).T + pose[:3] * np.array([1.0, 1.0, 0.0])

    def distance(corners, pose, goal):
        return np.linalg.norm(keypoints(corners, pose) - keypoints(corners, goal), axis=1).mean()

    moved, success_reward = 0, load_primitive_env_config("push").task.success_reward
    for row, state in enumerate(data["state"]):
        corners, before = data["outcome_corners"][state], data["outcome_pose"][state]
        goal, after = data["outcome_goal"][state], data["pose_after"][row]
        reward = PrimitiveConfig().progress_reward * (distance(corners, before, goal)
                                                      - distance(corners, after, goal))
        reward += success_reward * float(data["success_after"][row])
        assert data["reward"][row] == pytest.approx(reward, abs=1e-5), row
        moved += not np.allclose(after, before, atol=1e-4)
    assert moved > 0, "no candidate moved the object: the outcomes say nothing"
    assert data["outcome_aims"].shape == (*data["features_tokens"].shape[:2], 3)
    assert data["outcome_physics"].shape == (2, 5) and data["still_after"].dtype == bool


def test_scores_quality_takes_each_states_highest_scored_candidate():
    data = {"state": np.array([0, 0, 0, 1, 1]),
            "reward": np.array([0.1, 0.5, -0.2, 0.0, 0.3])}
    figures = scores_quality(np.array([3.0, 1.0, 2.0, -1.0, 5.0]), data)
    assert figures["chosen"] == pytest.approx((0.1 + 0.3) / 2)
    assert figures["best"] == pytest.approx((0.5 + 0.3) / 2)
    assert figures["first"] == pytest.approx((0.1 + 0.0) / 2)
    assert figures["mean"] == pytest.approx((0.4 / 3 + 0.15) / 2)


def test_following_the_policy_plays_the_policys_own_episode():
    agent, env = _agent(), _env()
    collect_episode(env, agent, 3, 1, 1.0, np.random.default_rng(0))
    followed = env.object_pose()
    own = _env()
    obs, _ = own.reset(seed=3)
    for _ in range(2):
        choice = agent.choose(obs)
        obs, _, terminated, truncated, _ = own.step({"point": choice["point"],
                                                     "motion": choice["motion"]})
        if terminated or truncated:
            break
    np.testing.assert_array_equal(followed, own.object_pose())


def test_the_fitted_critic_predicts_the_rewards_and_the_actor_follows_it(collected):
    agent, states, _ = collected
    data = stack_states(states)
    assert data["features_tokens"].shape[0] == 2 and data["state"].max() == 1
    before = critic_error(agent, data)
    losses = fit_critic(agent, data, epochs=60, batch_size=16, validation=data)
    after = critic_error(agent, data)
    assert after < 0.25 * before and losses["train"][-1] < losses["train"][0]
    assert losses["validation"][-1] == pytest.approx(after)
    actor_losses = fit_actor(agent, data, epochs=30, batch_size=2)
    assert actor_losses[-1] < actor_losses[0]  # -Q1 fell: the actor moved toward the critic's best
    assert all(p.requires_grad for p in agent.critic.parameters())


def test_the_rank_fit_orders_each_states_candidates(collected):
    agent, states, _ = collected
    data = stack_states(states)
    losses = fit_critic(agent, data, epochs=60, batch_size=64, loss="rank")
    assert losses["train"][-1] < 0.8 * losses["train"][0]
    # On its own data it chooses (nearly) the best candidate: within a tenth of the gap between
    # the best and a random one (two candidates may earn almost the same).
    quality = choice_quality(agent, data)
    assert quality["best"] - quality["chosen"] <= 0.1 * (quality["best"] - quality["mean"])


def test_bad_input_is_refused_by_name():
    with pytest.raises(InputError, match="no lookahead states"):
        stack_states([])
    with pytest.raises(InputError, match="loss"):
        fit_critic(_agent(), {"state": np.zeros(1, np.int64)}, 1, loss="hinge")
    with pytest.raises(InputError, match="follow_policy"):
        collect_episode(_env(), _agent(), 3, 1, 1.5, np.random.default_rng(0))
