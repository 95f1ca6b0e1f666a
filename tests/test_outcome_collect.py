"""Collecting lookahead data (rl/primitive/outcome/collect.py): the collected states hold every
candidate's reward and outcome from the same state, and an episode that follows the policy is
the policy's own episode."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
from corn_drake.config.primitive import PrimitiveConfig
from corn_drake.errors import InputError
from corn_drake.rl.primitive.outcome.collect import collect_episode, stack_states
from corn_drake.rl.envs.primitive_env import PrimitiveEnv


def _agent():
    from corn_drake.nn.encoders.encoder_files import make_policy_encoder
    from corn_drake.rl.primitive.agent import PrimitiveAgent

    torch.manual_seed(0)
    return PrimitiveAgent(make_policy_encoder("corn")).eval()


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


def test_bad_input_is_refused_by_name():
    with pytest.raises(InputError, match="no lookahead states"):
        stack_states([])
    with pytest.raises(InputError, match="follow_policy"):
        collect_episode(_env(), _agent(), 3, 1, 1.5, np.random.default_rng(0))
