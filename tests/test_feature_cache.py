"""The frozen-feature cache of teacher training (rl/training/ppo_trainer.py,
TeacherAgent.features), counted.

A frozen encoder (`corn`, `pn`, `p2v-lite`, `rot`) gives the same features for the same
observation, so the trainer computes them once when it collects a batch and every PPO epoch
reuses them: the encoder runs once per collected observation batch and never inside the
update. `e2e` trains its encoder, so its features must be recomputed in every minibatch of
every epoch (a cache would freeze it).

The environments are replaced by random observations of the contract's shapes: the counts
depend on the trainer, not on the simulation, and the test needs no Drake.
"""

import numpy as np
import pytest
import torch

from corn_drake.config.training import TrainConfig
from corn_drake.contract import ACTION_DIM, observation_shapes
from corn_drake.nn.encoders.encoder_files import make_policy_encoder
from corn_drake.rl.policy_kinds import ENCODER_KIND, FROZEN_ENCODER_POLICIES
from corn_drake.rl.ppo.agent import TeacherAgent, obs_to_tensors
from corn_drake.rl.ppo.segments import SegmentCollector
from corn_drake.rl.training.ppo_trainer import Trainer
from corn_drake.rl.envs.vec_env import StepResult

NUM_POINTS = 64  # enough for 16 patches of 32; the agent reads any cloud size
ENDS_EVERY = 3  # env 0's episodes end every third step, so final observations are encoded too


class RandomEnvs:
    """Stands in for EnvBatch: random observations, env 0's episodes ending every 3 steps."""

    def __init__(self, num_envs: int, seed: int = 0):
        self.num_envs, self.rng, self.steps = num_envs, np.random.default_rng(seed), 0

    def __len__(self):
        return self.num_envs

    def _obs(self):
        return {k: self.rng.normal(size=(self.num_envs, *shape)).astype(np.float32)
                for k, shape in observation_shapes(NUM_POINTS).items()}

    def reset(self):
        return self._obs()

    def step(self, actions):
        assert actions.shape == (self.num_envs, ACTION_DIM)
        self.steps += 1
        ended = np.zeros(self.num_envs, bool)
        ended[0] = self.steps % ENDS_EVERY == 0
        final = {0: {k: v[0] for k, v in self._obs().items()}} if ended[0] else {}
        stats = [{"object": "box", "return": 0.0, "success": False, "length": ENDS_EVERY}] * int(ended[0])
        return StepResult(obs=self._obs(), rewards=self.rng.normal(size=self.num_envs),
                          terminated=ended, truncated=np.zeros(self.num_envs, bool),
                          final_obs=final, episode_stats=stats)


def _train(kind, tmp_path, monkeypatch, updates=2, rollout_steps=4, num_envs=2):
    """Trains `updates` updates; returns (encoder calls per collection, per PPO update,
    history, encoder parameters before, trained encoder)."""
    monkeypatch.setattr(Trainer, "_make_rollouts",
                        lambda self, n: SegmentCollector(RandomEnvs(n), self.agent, self.device))
    cfg = TrainConfig(policy=kind, total_steps=updates * rollout_steps * num_envs,
                      envs_per_worker=num_envs, rollout_steps=rollout_steps, checkpoint_every=100)
    cfg.ppo.epochs, cfg.ppo.minibatches = 3, 2
    cfg.ppo.kl_stop_factor = 1e9  # no early stop: every epoch and minibatch runs
    torch.manual_seed(0)
    encoder = make_policy_encoder(ENCODER_KIND[kind])
    calls = []
    encoder.register_forward_pre_hook(lambda module, args: calls.append(1))
    before = [p.detach().clone() for p in encoder.parameters()]
    trainer = Trainer(cfg, tmp_path, encoder)
    in_update, update = [], trainer.ppo.update

    def counted_update(*args, **kwargs):
        start = len(calls)
        stats = update(*args, **kwargs)
        in_update.append(len(calls) - start)
        return stats

    monkeypatch.setattr(trainer.ppo, "update", counted_update)
    trainer.train(progress=False)
    in_collection = len(calls) - sum(in_update)
    return in_collection, in_update, trainer.history, before, encoder


def _expected_collection_calls(updates, rollout_steps):
    # Per update: one batch per rollout step, one for the final observations of any step where
    # an episode ended, one for the bootstrap value after the rollout.
    endings = sum(1 for t in range(1, updates * rollout_steps + 1) if t % ENDS_EVERY == 0)
    return updates * (rollout_steps + 1) + endings


@pytest.mark.parametrize("kind", FROZEN_ENCODER_POLICIES)
def test_a_frozen_encoder_runs_once_per_collected_batch_and_never_in_ppo_epochs(
        kind, tmp_path, monkeypatch):
    in_collection, in_update, history, before, encoder = _train(kind, tmp_path, monkeypatch)
    assert in_collection == _expected_collection_calls(2, 4)
    assert in_update == [0, 0]
    assert [h["gradient_steps"] for h in history] == [6, 6]  # 3 epochs x 2 minibatches ran
    assert all(torch.equal(a, b) for a, b in zip(before, encoder.parameters()))


def test_a_trained_encoder_runs_in_every_minibatch_of_every_epoch(tmp_path, monkeypatch):
    in_collection, in_update, history, before, encoder = _train("e2e", tmp_path, monkeypatch)
    assert in_collection == _expected_collection_calls(2, 4)  # no cache, same batches
    assert in_update == [h["gradient_steps"] for h in history] == [6, 6]
    assert not all(torch.equal(a, b) for a, b in zip(before, encoder.parameters()))


def _agent_and_obs(kind):
    torch.manual_seed(0)
    encoder = make_policy_encoder(ENCODER_KIND[kind])
    calls = []
    encoder.register_forward_pre_hook(lambda module, args: calls.append(1))
    agent = TeacherAgent(kind, encoder, getattr(encoder, "feature_dim", None))
    return agent, obs_to_tensors(RandomEnvs(3).reset()), calls


@pytest.mark.parametrize("kind", FROZEN_ENCODER_POLICIES)
def test_cached_features_give_the_agent_the_same_output_without_the_encoder(kind):
    agent, obs, calls = _agent_and_obs(kind)
    with torch.no_grad():
        mu, value = agent(obs)
        cached = {**obs, "features": agent.features(obs)}
        assert len(calls) == 2
        mu_cached, value_cached = agent(cached)
    assert len(calls) == 2  # the cached forward never ran the encoder
    torch.testing.assert_close(mu_cached, mu)
    torch.testing.assert_close(value_cached, value)


def test_a_trained_encoder_ignores_a_features_entry():
    """e2e must never read stale features: it recomputes them whatever the observation holds."""
    agent, obs, calls = _agent_and_obs("e2e")
    stale = {**obs, "features": torch.zeros_like(agent.features(obs))}
    calls.clear()
    with torch.no_grad():
        torch.testing.assert_close(agent(stale)[0], agent(obs)[0])
    assert len(calls) == 2
