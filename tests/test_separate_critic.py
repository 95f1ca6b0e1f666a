"""ppo.separate_critic: a second head gives the value, trained by its own Adam on every
minibatch whatever the policy's KL early stop does, and never moving the policy."""

import copy

import numpy as np
import pytest
import torch

from corn_drake.config.training import PPOConfig
from corn_drake.contract import observation_shapes
from corn_drake.rl.ppo.agent import TeacherAgent, obs_to_tensors
from corn_drake.rl.ppo.ppo import PPO, sample_actions


def _obs(n: int, seed: int = 0) -> dict[str, torch.Tensor]:
    """A batch of `state`-policy observations (every teacher key but the cloud), random."""
    rng = np.random.default_rng(seed)
    shapes = {k: v for k, v in observation_shapes().items() if k != "cloud"}
    return obs_to_tensors({k: rng.normal(size=(n, *shape)) for k, shape in shapes.items()})


def _batch(agent, n=128, seed=0):
    obs = _obs(n, seed)
    g = torch.Generator().manual_seed(seed)
    actions, logp, values = sample_actions(agent, obs, g)
    advantages = torch.sign(actions[:, 0]) * torch.sign(obs["goal"][:, 0])
    returns = 3.0 * obs["goal"][:, 0] + 1.0  # a value the critic can fit from its input
    return obs, actions, logp, advantages, returns


def _params(module):
    return [p.detach().clone() for p in module.parameters()]


def test_the_value_comes_from_the_critic_head_and_the_mean_from_the_actor():
    torch.manual_seed(0)
    agent = TeacherAgent("state", separate_critic=True)
    obs = _obs(5)
    mu, value = agent(obs)
    features, context = agent.features(obs), agent.normalized_context(obs["context"])
    torch.testing.assert_close(mu, agent.head(features, context)[0])
    torch.testing.assert_close(value, agent.critic_head(features, context)[1])
    assert not torch.allclose(value, agent.head(features, context)[1])
    actor, critic = map(set, (map(id, agent.actor_parameters()), map(id, agent.critic_parameters())))
    assert actor and critic and not actor & critic
    assert id(agent.log_std) in actor
    # A shared-critic agent has no critic parameters and builds the same actor as before.
    assert TeacherAgent("state", separate_critic=False).critic_parameters() == []


def test_the_separate_critic_is_the_default_as_the_shipped_runs_were_trained():
    """One source for the number: PPOConfig's default, which the agent takes too."""
    from corn_drake.config.plumbing.loader import load_config
    from corn_drake.config.training import TrainConfig
    from corn_drake.package_data import data_dir

    assert PPOConfig().separate_critic is True
    assert TeacherAgent("state").critic_head is not None
    PPO(TeacherAgent("state"), PPOConfig())  # the defaults agree
    for name in ("push_corn", "push_state"):
        shipped = data_dir("models") / "weights" / name / "config.yaml"
        assert load_config(TrainConfig, shipped).ppo.separate_critic is True


def test_the_critic_trains_every_minibatch_after_the_policy_stops_early():
    torch.manual_seed(0)
    agent = TeacherAgent("state", separate_critic=True)
    cfg = PPOConfig(epochs=6, minibatches=2, lr=1e-2, kl_target=1e-7, separate_critic=True)
    ppo = PPO(agent, cfg)
    obs, actions, logp, adv, ret = _batch(agent)
    before = ppo.losses(obs, actions, logp, adv, ret)["value"].item()
    stats = ppo.update(obs, actions, logp, adv, ret, torch.Generator().manual_seed(1))
    assert stats["early_stop"] == 1.0 and stats["minibatches"] < 12
    assert stats["critic_steps"] == 12
    assert ppo.losses(obs, actions, logp, adv, ret)["value"].item() < before
    # With a shared critic the same update ends at the stop: no critic steps of its own.
    torch.manual_seed(0)
    shared = TeacherAgent("state", separate_critic=False)
    stats = PPO(shared, PPOConfig(epochs=6, minibatches=2, lr=1e-2, kl_target=1e-7,
                                  separate_critic=False)).update(
        *_batch(shared), torch.Generator().manual_seed(1))
    assert stats["early_stop"] == 1.0 and stats["critic_steps"] == 0


def test_critic_steps_never_move_the_policy():
    torch.manual_seed(0)
    agent = TeacherAgent("state", separate_critic=True)
    cfg = PPOConfig(epochs=3, minibatches=2, policy_coef=0.0, bound_coef=0.0,
                    separate_critic=True)
    ppo = PPO(agent, cfg)
    actor_before = [p.detach().clone() for p in agent.actor_parameters()]
    critic_before = _params(agent.critic_head)
    ppo.update(*_batch(agent), torch.Generator().manual_seed(1))
    for a, b in zip(actor_before, agent.actor_parameters()):
        torch.testing.assert_close(a, b.detach(), rtol=0, atol=0)
    assert any(not torch.equal(a, b) for a, b in zip(critic_before, _params(agent.critic_head)))


def test_mismatched_settings_are_refused():
    with pytest.raises(ValueError, match="separate_critic"):
        PPO(TeacherAgent("state", separate_critic=False), PPOConfig(separate_critic=True))
    with pytest.raises(ValueError, match="separate_critic is off"):
        PPO(TeacherAgent("state", separate_critic=True), PPOConfig(separate_critic=False))
    with pytest.raises(ValueError, match="critic_lr"):
        PPO(TeacherAgent("state", separate_critic=True),
            PPOConfig(separate_critic=True, critic_lr=0.0))
    # A saved PPO state from the other setting does not load silently.
    shared_state = PPO(TeacherAgent("state", separate_critic=False),
                       PPOConfig(separate_critic=False)).state_dict()
    separate = PPO(TeacherAgent("state", separate_critic=True), PPOConfig(separate_critic=True))
    with pytest.raises(ValueError, match="disagree"):
        separate.load_state_dict(shared_state)


def test_the_critic_optimiser_round_trips_through_the_state_dict():
    torch.manual_seed(0)
    agent = TeacherAgent("state", separate_critic=True)
    cfg = PPOConfig(epochs=2, separate_critic=True, critic_lr=1e-3)
    ppo = PPO(agent, cfg)
    ppo.update(*_batch(agent), torch.Generator().manual_seed(1))
    # A copy, as a checkpoint file would hold: a loaded Adam state shares the saved tensors.
    state = copy.deepcopy(ppo.state_dict())
    clone = TeacherAgent("state", separate_critic=True)
    clone.load_state_dict(agent.state_dict())
    ppo2 = PPO(clone, cfg)
    ppo2.load_state_dict(state)
    batch = _batch(agent, seed=3)
    ppo.update(*batch, torch.Generator().manual_seed(2))
    ppo2.update(*batch, torch.Generator().manual_seed(2))
    for a, b in zip(agent.parameters(), clone.parameters()):
        torch.testing.assert_close(a, b)
