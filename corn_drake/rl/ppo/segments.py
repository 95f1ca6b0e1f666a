"""Rollout segments: a batch of envs stepped for a whole PPO rollout by the policy, where the envs
are (in this process, or inside a Ray worker: rl/workers/segment_workers.py).

A SegmentCollector owns an env batch, a policy and the batch's current observation. collect()
takes the update's unit noise (T, E, A) — drawn by the learner, so every path acts with the same
draws — steps the envs T times with mean + exp(log_std) * noise, and returns a Segment: what the
learner's GAE and PPO update need (observations, actions, log-probs, values, raw rewards, ends,
the values of episodes cut by a time-out, the bootstrap values after the last step), the
finished episodes' stats, the weights version it acted with, and where the collector's time
went (env stepping against inference).

Rewards travel raw: the learner's RewardScaler (a running return per env) scales them in step
order, so one scaler sees the whole batch as it does in-process.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np
import torch

from corn_drake.rl.ppo.agent import obs_to_tensors
from corn_drake.rl.ppo.ppo import actions_from_noise
from corn_drake.rl.envs.vec_env import stack_obs


@dataclasses.dataclass
class Segment:
    obs: dict[str, np.ndarray]  # (T, E, ...) the observations the actions were taken in
    # (T, E, F...) a frozen encoder's features of `obs` (computed for acting, kept so the PPO
    # epochs do not run the encoder again); None for a trained encoder.
    features: np.ndarray | None
    actions: np.ndarray  # (T, E, A) before clipping (the log-probs are theirs)
    logp: np.ndarray  # (T, E)
    values: np.ndarray  # (T, E)
    rewards: np.ndarray  # (T, E) raw env rewards
    terminated: np.ndarray  # (T, E) bool
    truncated: np.ndarray  # (T, E) bool
    final_values: np.ndarray  # (T, E) V(last observation) where an episode was cut, else 0
    last_values: np.ndarray  # (E,) V(observation after the last step)
    episode_stats: list[dict[str, Any]]
    sim_errors: int
    version: int  # the update whose weights acted
    # The collector's own seconds: stepping the envs, the policy's forward passes, and the whole
    # collect() (its pace: E * T / total); joined segments keep the slowest part's.
    seconds: dict[str, float]
    # Each collector's seconds and env count, in env order (one entry for one collector): the
    # workers' own paces, as `bench scale` reports them.
    parts: list[dict] = dataclasses.field(default_factory=list)

    def __post_init__(self):
        if not self.parts:
            self.parts = [{**self.seconds, "envs": int(self.rewards.shape[1])}]

    @property
    def shape(self) -> tuple[int, int]:
        """(T, E): steps and envs."""
        return self.rewards.shape


def concat_segments(parts: list[Segment]) -> Segment:
    """Segments of the same update and length joined along the env axis, in the order given
    (worker 0's envs first, as the learner's noise columns); seconds are the slowest part's."""
    versions = {p.version for p in parts}
    if len(versions) != 1:
        raise RuntimeError(f"segments of one update acted with different weights {versions}")

    def cat(arrays, axis=1):
        return np.concatenate(arrays, axis=axis)

    return Segment(
        obs={k: cat([p.obs[k] for p in parts]) for k in parts[0].obs},
        features=None if parts[0].features is None else cat([p.features for p in parts]),
        actions=cat([p.actions for p in parts]), logp=cat([p.logp for p in parts]),
        values=cat([p.values for p in parts]), rewards=cat([p.rewards for p in parts]),
        terminated=cat([p.terminated for p in parts]), truncated=cat([p.truncated for p in parts]),
        final_values=cat([p.final_values for p in parts]),
        last_values=cat([p.last_values for p in parts], axis=0),
        episode_stats=[s for p in parts for s in p.episode_stats],
        sim_errors=sum(p.sim_errors for p in parts), version=parts[0].version,
        seconds={k: max(p.seconds[k] for p in parts) for k in parts[0].seconds},
        parts=[q for p in parts for q in p.parts])


class SegmentCollector:
    """An env batch (vec_env.EnvBatch) stepped by `agent` (a TeacherAgent on `device`)."""

    def __init__(self, envs, agent, device: torch.device | str = "cpu"):
        self.envs, self.agent, self.device = envs, agent, torch.device(device)
        self.version = 0  # the update whose weights the agent holds
        self._obs: dict[str, np.ndarray] | None = None  # the batch's current observation

    def __len__(self) -> int:
        return len(self.envs)

    def sync(self, agent, version: int) -> None:
        """In-process: the learner's own agent acts, so only the version moves."""
        if agent is not self.agent:
            raise ValueError("an in-process collector acts with the learner's own agent")
        self.version = version

    def reset(self) -> dict[str, np.ndarray]:
        """Restarts every env's current episode; the next collect() starts from here."""
        self._obs = self.envs.reset()
        return self._obs

    def set_weights(self, state: dict, version: int) -> None:
        """The learner's agent state after update `version` (once per update: a collect with
        the same version reuses it)."""
        if version != self.version:
            self.agent.load_state_dict(state)
            self.version = version

    def _forward(self, obs_np: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
        """Observation tensors on the device, with a frozen encoder's features added."""
        obs = obs_to_tensors(obs_np, self.device)
        if self.agent.frozen_encoder:
            with torch.no_grad():
                obs["features"] = self.agent.features(obs)
        return obs

    def collect(self, noise: np.ndarray) -> Segment:
        """T = len(noise) steps of every env, acting with mean + std * noise[t] (noise: (T, E,
        A) unit Gaussian draws)."""
        T, E = noise.shape[:2]
        if E != len(self.envs):
            raise ValueError(f"noise: expected {len(self.envs)} env columns, got {E}")
        started = time.perf_counter()
        stepping = inference = 0.0
        if self._obs is None:
            self.reset()
        observations, features, rows, stats, errors = [], [], [], [], 0
        final_values = np.zeros((T, E), np.float32)
        for t in range(T):
            t0 = time.perf_counter()
            obs = self._forward(self._obs)
            actions, logp, values = actions_from_noise(self.agent, obs,
                                                       torch.as_tensor(noise[t]))
            actions_np = actions.cpu().numpy()
            t1 = time.perf_counter()
            step = self.envs.step(actions_np)
            t2 = time.perf_counter()
            if step.final_obs:
                ended = sorted(step.final_obs)
                final = self._forward(stack_obs([step.final_obs[i] for i in ended]))
                with torch.no_grad():
                    final_values[t, ended] = self.agent(final)[1].cpu().numpy()
            inference += (t1 - t0) + (time.perf_counter() - t2)
            stepping += t2 - t1
            observations.append(self._obs)
            if "features" in obs:
                features.append(obs["features"].cpu().numpy())
            rows.append((actions_np, logp.cpu().numpy(), values.cpu().numpy(), step.rewards,
                         step.terminated, step.truncated))
            stats += step.episode_stats
            errors += step.sim_errors
            self._obs = step.obs
        t0 = time.perf_counter()
        with torch.no_grad():
            last_values = self.agent(self._forward(self._obs))[1].cpu().numpy()
        inference += time.perf_counter() - t0
        actions, logp, values, rewards, terminated, truncated = (np.stack(c) for c in zip(*rows))
        return Segment(
            obs={k: np.stack([o[k] for o in observations]) for k in observations[0]},
            features=np.stack(features) if features else None,
            actions=actions, logp=logp, values=values, rewards=rewards, terminated=terminated,
            truncated=truncated, final_values=final_values, last_values=last_values,
            episode_stats=stats, sim_errors=errors, version=self.version,
            seconds={"env_step": stepping, "inference": inference,
                     "total": time.perf_counter() - started})
