"""Collecting contact primitives for the off-policy learner, where the envs are.

A PrimitiveCollector owns an env batch, a PrimitiveAgent (the frozen encoder and a copy of the
actor and critic it chooses with) and the batch's current observation. collect() runs `rounds`
rounds — one primitive in every env per round, chosen while exploring (uniformly at random
during the run's first `random_steps` primitives, else rl/primitive/td3.select_primitives with the
temperature and motion noise) — and returns PrimitiveTransitions: per-location features of each
state and of the state it led to (the encoder runs once per observation, here, so the learner
never runs it), the choices, rewards and ends, and the finished episodes' stats. With a
HindsightRule (rl/primitive/hindsight.py) each finished episode also comes back relabelled with goals it
reached (`relabeled`), drawn from the same random stream.

The trainer's in-process path (`--workers 0`) runs one collector with its own agent, learner
and random stream, one round per loop, exactly as the trainer always did; Ray workers
(rl/workers/primitive_workers.py) each run one with a CPU copy of the networks and a stream of their own.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from corn_drake.rl.primitive.hindsight import HindsightEpisodes, HindsightRule, achieved_states
from corn_drake.rl.primitive.td3 import choosable

# select(features, greedy=..., temperature=..., motion_noise=..., rng=...) -> (locations,
# motions, scores): TD3Learner.select, or select_primitives over an agent's own networks.
Select = Callable[..., tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclasses.dataclass
class Exploration:
    """How a round chooses: uniformly random (the replay's first fill) or from the policy."""
    random: bool
    temperature: float
    motion_noise: float


@dataclasses.dataclass
class PrimitiveTransitions:
    features: dict[str, np.ndarray]  # (N, L, ...) per-location features of the states acted in
    locations: np.ndarray  # (N,) the chosen location (index among the candidates)
    motions: np.ndarray  # (N, 3) the motion executed, in [-1, 1]
    rewards: np.ndarray  # (N,)
    terminated: np.ndarray  # (N,) bool: no bootstrap (success, out of workspace)
    next_features: dict[str, np.ndarray]  # the state each led to (an ended episode's last one)
    episode_stats: list[dict[str, Any]]
    version: int  # the learner's weights version the choices were made with
    # Hindsight copies of the episodes that ended in these rounds (rl/primitive/hindsight.py): the same
    # columns, not primitives of their own (the run's step counts only the ones above).
    relabeled: PrimitiveTransitions | None = None

    def __len__(self) -> int:
        return int(self.locations.shape[0])


def _numpy(features: dict[str, torch.Tensor]) -> dict[str, np.ndarray]:
    return {k: v.cpu().numpy() for k, v in features.items()}


def uniform_choices(features, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Uniform over each state's choosable locations (td3.choosable: the usable ones, or all of
    them if none is usable), motions uniform in [-1, 1]^3."""
    usable = choosable(features["mask"]).numpy()
    weights = usable / usable.sum(axis=1, keepdims=True)
    locations = np.array([rng.choice(usable.shape[1], p=w) for w in weights])
    motions = rng.uniform(-1.0, 1.0, (len(weights), 3)).astype(np.float32)
    return locations, motions


class PrimitiveCollector:
    def __init__(self, envs, agent, select: Select | None = None,
                 hindsight: HindsightRule | None = None):
        """`envs`: an EnvBatch of PrimitiveEnvs; `agent`: a PrimitiveAgent (its encoder makes
        the features); `select`: how the policy chooses (default: the agent's own networks);
        `hindsight`: relabel finished episodes with goals they reached (None: off)."""
        from corn_drake.rl.primitive.td3 import select_primitives

        self.envs, self.agent = envs, agent
        self.hindsight = None if hindsight is None else HindsightEpisodes(hindsight, len(envs))
        self.select = select or (lambda features, **kw: select_primitives(
            agent.scores_and_motions(features), **kw))
        self.version = -1
        # The envs' current observation as the policy sees it (None before the first reset).
        self._features = self._candidates = None

    def set_weights(self, state: dict, version: int) -> None:
        """The learner's actor and critic after update `version` (network_state())."""
        if version != self.version:
            self.agent.load_network_state(state, f"the learner's weights {version}")
            self.version = version

    def _start(self) -> None:
        if self._features is None:
            obs = self.envs.reset()
            self._features, self._candidates = self.agent.features(obs)
            if self.hindsight is not None:
                for slot, state in enumerate(achieved_states(obs)):
                    self.hindsight.begin(slot, state)

    def _keep_for_hindsight(self, step, features, locations, motions, target,
                            rng: np.random.Generator) -> list[dict]:
        """Adds this round's transitions to their episodes; returns the relabelled columns of
        the episodes that ended (and begins the envs' new ones)."""
        episodes, relabeled = self.hindsight, []
        after = achieved_states(step.obs)
        ended = sorted(step.final_obs)
        finals = dict(zip(ended, achieved_states(
            {k: np.stack([step.final_obs[i][k] for i in ended]) for k in
             ("object_position", "goal", "object_speed", "object_keypoints")}))) if ended else {}
        stats = dict(zip(ended, step.episode_stats))  # both in env order
        for slot in range(len(locations)):
            episodes.add(slot, {k: v[slot] for k, v in features.items()}, locations[slot],
                         motions[slot], step.terminated[slot],
                         {k: v[slot] for k, v in target.items()}, finals.get(slot, after[slot]))
            if slot in finals:
                columns = episodes.finish(slot, stats[slot]["success"] > 0,
                                          not stats[slot]["sim_error"], rng)
                if columns is not None:
                    relabeled.append(columns)
                episodes.begin(slot, after[slot])
        return relabeled

    def collect(self, rounds: int, exploration: Exploration,
                rng: np.random.Generator) -> PrimitiveTransitions:
        self._start()
        parts, stats, relabeled = [], [], []
        for _ in range(rounds):
            features, candidates = self._features, self._candidates
            if exploration.random:
                locations, motions = uniform_choices(features, rng)
            else:
                locations, motions, _ = self.select(
                    features, greedy=False, temperature=exploration.temperature,
                    motion_noise=exploration.motion_noise, rng=rng)
            points = candidates.numpy()[np.arange(len(locations)), np.asarray(locations)]
            actions = [{"point": int(p), "motion": m} for p, m in zip(points, motions)]
            step = self.envs.step(actions)
            next_features, next_candidates = self.agent.features(step.obs)
            target = {k: v.clone() for k, v in next_features.items()}
            if step.final_obs:  # an ended episode's transition leads to its last observation
                ended = sorted(step.final_obs)
                final, _ = self.agent.features(
                    {k: np.stack([step.final_obs[i][k] for i in ended])
                     for k in step.final_obs[ended[0]]})
                for key in target:
                    target[key][ended] = final[key]
            acted_in, locations, led_to = _numpy(features), np.asarray(locations), _numpy(target)
            parts.append((acted_in, locations, motions, np.asarray(step.rewards),
                          np.asarray(step.terminated), led_to))
            if self.hindsight is not None:
                relabeled.extend(self._keep_for_hindsight(step, acted_in, locations, motions,
                                                          led_to, rng))
            stats.extend(step.episode_stats)
            self._features, self._candidates = next_features, next_candidates

        def cat(i, key=None):
            arrays = [p[i] if key is None else p[i][key] for p in parts]
            return np.concatenate(arrays, axis=0)

        return PrimitiveTransitions(
            features={k: cat(0, k) for k in parts[0][0]}, locations=cat(1), motions=cat(2),
            rewards=cat(3), terminated=cat(4), next_features={k: cat(5, k) for k in parts[0][5]},
            episode_stats=stats, version=self.version,
            relabeled=_joined(relabeled, self.version) if relabeled else None)


def _joined(columns: list[dict], version: int) -> PrimitiveTransitions:
    """Relabelled episodes' columns (HindsightEpisodes.finish) as one PrimitiveTransitions."""
    def cat(key: str, sub: str | None = None) -> np.ndarray:
        return np.concatenate([c[key] if sub is None else c[key][sub] for c in columns])

    return PrimitiveTransitions(
        features={k: cat("features", k) for k in columns[0]["features"]},
        locations=cat("locations"), motions=cat("motions"), rewards=cat("rewards"),
        terminated=cat("terminated"),
        next_features={k: cat("next_features", k) for k in columns[0]["next_features"]},
        episode_stats=[], version=version)
