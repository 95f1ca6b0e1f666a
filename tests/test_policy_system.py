"""The PolicySystem closing the loop in the evaluation diagram acts as the training path does."""

import numpy as np
import pytest
import torch

from corn_drake.contract import ACTION_DIM
from corn_drake.evaluation import run_episode
from corn_drake.rl.agent import TeacherAgent
from corn_drake.rl.env import TeacherEnv


def test_policy_system_matches_training_path_and_runs_closed_loop():
    torch.manual_seed(0)
    agent = TeacherAgent("state")
    agent.eval()
    train_env = TeacherEnv()
    eval_env = TeacherEnv(agent=agent)
    obs, _ = train_env.reset(seed=7)
    eval_env.reset(seed=7)
    policy = eval_env.handles.policy
    ctx = policy.GetMyContextFromRoot(eval_env.context)
    in_diagram = policy.GetOutputPort("action").Eval(ctx)
    np.testing.assert_allclose(in_diagram, agent.act(obs), rtol=1e-6, atol=1e-6)
    for key, value in policy.observation(ctx).items():
        np.testing.assert_allclose(value, obs[key], rtol=1e-6, atol=1e-6, err_msg=key)
    # One policy step of each path lands in the same state.
    train_env.step(agent.act(obs))
    eval_env.step()
    np.testing.assert_allclose(
        eval_env.scene.plant.GetPositionsAndVelocities(eval_env.plant_context),
        train_env.scene.plant.GetPositionsAndVelocities(train_env.plant_context), atol=1e-9)
    with pytest.raises(ValueError, match="inside the diagram"):
        eval_env.step(np.zeros(ACTION_DIM))  # the diagram's policy acts, not the caller
    # Whole episodes on both paths: the same seed gives the same episode.
    eval_env.cfg.task.episode_steps = train_env.cfg.task.episode_steps = 5
    closed = run_episode(eval_env, seed=2)
    stepped = run_episode(train_env, agent, seed=2)
    assert closed.steps == stepped.steps and 1 <= closed.steps <= 5
    assert closed.total_reward == pytest.approx(stepped.total_reward, abs=1e-6)
    assert np.isfinite(closed.total_reward) and "success" in closed.status
    with pytest.raises(ValueError, match="policy"):
        run_episode(eval_env, agent)  # two policies for one env


def test_sampled_actions_follow_the_policy_distribution_and_its_seed():
    torch.manual_seed(0)
    agent = TeacherAgent("state")
    obs, _ = TeacherEnv().reset(seed=3)
    mean = agent.act(obs)
    with torch.no_grad():
        agent.log_std.fill_(-2.0)  # std 0.135: samples stay near the mean, mostly unclipped
    agent.action_noise = torch.Generator().manual_seed(5)
    draws = np.stack([agent.act(obs) for _ in range(400)])
    assert np.all(np.abs(draws) <= 1.0)
    inside = np.abs(mean) < 0.6  # dimensions whose samples are rarely clipped
    np.testing.assert_allclose(draws.mean(0)[inside], mean[inside], atol=0.03)
    np.testing.assert_allclose(draws.std(0)[inside], np.exp(-2.0), rtol=0.15)
    agent.action_noise = torch.Generator().manual_seed(5)
    np.testing.assert_array_equal(agent.act(obs), draws[0])  # same seed, same first sample
    agent.action_noise = None
    np.testing.assert_array_equal(agent.act(obs), mean)
