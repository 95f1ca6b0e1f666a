"""The PolicySystem closing the loop in the evaluation diagram acts as the training path does."""

import numpy as np
import pytest
import torch

from corn_drake.contract import ACTION_DIM
from corn_drake.evaluation.episodes import run_episode
from corn_drake.rl.ppo.agent import TeacherAgent, obs_to_tensors
from corn_drake.rl.envs.teacher_env import TeacherEnv


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


def test_sampled_actions_follow_the_policy_distribution_and_are_pure():
    torch.manual_seed(0)
    agent = TeacherAgent("state")
    obs, _ = TeacherEnv().reset(seed=3)
    mean = agent.act(obs)
    with torch.no_grad():
        agent.log_std.fill_(-2.0)  # std 0.135: samples stay near the mean, mostly unclipped
    noise = np.random.default_rng(5).standard_normal((400, ACTION_DIM))
    draws = np.stack([agent.act(obs, n) for n in noise])
    assert np.all(np.abs(draws) <= 1.0)
    inside = np.abs(mean) < 0.6  # dimensions whose samples are rarely clipped
    np.testing.assert_allclose(draws.mean(0)[inside], mean[inside], atol=0.03)
    np.testing.assert_allclose(draws.std(0)[inside], np.exp(-2.0), rtol=0.15)
    np.testing.assert_array_equal(agent.act(obs, noise[0]), draws[0])  # same noise, same action
    np.testing.assert_array_equal(agent.act(obs), mean)  # no noise: the mean, as before
    assert not hasattr(agent, "action_noise")  # no random state on the agent


def _latched_actions(env, seed: int, steps: int = 3) -> np.ndarray:
    """The physical actions the IK latched over the first `steps` policy steps of an episode."""
    env.reset(seed=seed)
    ik = env.handles.ik
    actions = []
    for _ in range(steps):
        env.step()  # the diagram's PolicySystem acts
        actions.append(ik.GetOutputPort("previous_action").Eval(ik.GetMyContextFromRoot(env.context)))
    return np.array(actions)


def test_stochastic_evaluation_samples_from_a_random_source_seeded_per_episode():
    torch.manual_seed(0)
    agent = TeacherAgent("state")
    agent.eval()
    with torch.no_grad():
        agent.log_std.fill_(-1.0)
    stochastic = TeacherEnv(agent=agent, stochastic_policy=True)
    deterministic = TeacherEnv(agent=agent)
    assert stochastic.handles.policy.stochastic and not deterministic.handles.policy.stochastic
    assert not deterministic.handles.policy.HasInputPort("unit_noise")
    # The noise is a RandomSource in the diagram, sampling at the policy period.
    assert stochastic.diagram.HasSubsystemNamed("policy_noise")
    assert not deterministic.diagram.HasSubsystemNamed("policy_noise")

    first, again, other = (_latched_actions(stochastic, s) for s in (11, 11, 12))
    np.testing.assert_array_equal(first, again)  # same episode seed: the same samples
    assert np.abs(first - other).max() > 1e-3  # another seed: other samples
    mean_actions = _latched_actions(deterministic, 11)
    np.testing.assert_array_equal(mean_actions, _latched_actions(deterministic, 11))
    assert np.abs(first - mean_actions).max() > 1e-3  # same episode, sampled vs mean

    # At a state: the action is mean + exp(log_std) * the source's draw (then clipped).
    stochastic.reset(seed=11)
    policy = stochastic.handles.policy
    ctx = policy.GetMyContextFromRoot(stochastic.context)
    noise = policy.GetInputPort("unit_noise").Eval(ctx)
    obs = policy.observation(ctx)
    with torch.no_grad():
        mu, _ = agent(obs_to_tensors({k: v[None] for k, v in obs.items()}))
    expected = np.clip(mu[0].numpy() + np.exp(-1.0) * noise, -1, 1)
    np.testing.assert_allclose(policy.GetOutputPort("action").Eval(ctx), expected, atol=1e-6)
    assert np.abs(noise).max() > 0.1


def test_stochastic_policy_needs_an_agent():
    from corn_drake.builders.teacher import build_teacher_diagram

    with pytest.raises(ValueError, match="needs an agent"):
        build_teacher_diagram(stochastic_policy=True)
