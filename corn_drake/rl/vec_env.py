"""Batches of TeacherEnvs stepped together, in-process (EnvBatch) or on Ray actors (ray_workers).

Auto-reset: an env whose episode ended is reset inside `step`; the returned observation is the new
episode's first one, and `final_obs` keeps the last observation of the old episode (the learner
bootstraps time-outs from its value).
"""

from __future__ import annotations

import copy
import dataclasses
from typing import Any

import numpy as np

from corn_drake.config import TeacherDiagramConfig


def library_train_ids(library: str) -> list[str]:
    """The train objects of an object library; none is an error (nothing to train on)."""
    from corn_drake.assets.library import list_objects
    from corn_drake.errors import InputError

    ids = list_objects(library, "train")
    if not ids:
        raise InputError(f"object library {library} has no train objects")
    return ids


@dataclasses.dataclass
class EnvFactory:
    """Picklable recipe for the envs of one batch: the config, and seeds derived from `seed`.

    With a library object config and no object_id, env i gets the library's i-th train object
    (cycling), so a batch trains on many objects at once.
    """

    config: TeacherDiagramConfig
    seed: int = 0

    def make(self, index: int):
        from corn_drake.rl.env import TeacherEnv

        cfg = copy.deepcopy(self.config)
        cfg.seed = self.seed + index
        obj = cfg.scene.object
        if obj.kind == "library" and not obj.object_id:
            ids = library_train_ids(obj.library)
            obj.object_id = ids[index % len(ids)]
        return TeacherEnv(cfg)


def stack_obs(observations: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    return {k: np.stack([o[k] for o in observations]) for k in observations[0]}


@dataclasses.dataclass
class StepResult:
    obs: dict[str, np.ndarray]  # (E, ...) next observations (first of a new episode if done)
    rewards: np.ndarray  # (E,)
    terminated: np.ndarray  # (E,) bool
    truncated: np.ndarray  # (E,) bool
    final_obs: dict[int, dict[str, np.ndarray]]  # env index -> last obs of an ended episode
    episode_stats: list[dict[str, Any]]  # one entry per ended episode
    sim_errors: int = 0


class EnvBatch:
    def __init__(self, factory: EnvFactory, num_envs: int, first_index: int = 0):
        self.factory = factory
        self.envs = [factory.make(first_index + i) for i in range(num_envs)]
        self._returns = np.zeros(num_envs)
        self._lengths = np.zeros(num_envs, dtype=int)
        self._episode_seed = np.arange(num_envs) * 100_003 + factory.seed * 7919 + first_index

    def __len__(self) -> int:
        return len(self.envs)

    def reset(self) -> dict[str, np.ndarray]:
        self._returns[:] = 0
        self._lengths[:] = 0
        return stack_obs([env.reset(seed=int(s))[0] for env, s in zip(self.envs, self._episode_seed)])

    def step(self, actions: np.ndarray) -> StepResult:
        obs_list, rewards = [], np.zeros(len(self.envs))
        terminated = np.zeros(len(self.envs), bool)
        truncated = np.zeros(len(self.envs), bool)
        final_obs, stats, errors = {}, [], 0
        for i, (env, action) in enumerate(zip(self.envs, actions)):
            obs, reward, term, trunc, info = env.step(action)
            rewards[i], terminated[i], truncated[i] = reward, term, trunc
            self._returns[i] += reward
            self._lengths[i] += 1
            if "sim_error" in info:
                errors += 1
            if term or trunc:
                status = info.get("status", {})
                stats.append({"return": self._returns[i], "length": int(self._lengths[i]),
                              "success": float(status.get("success", 0.0)),
                              "sim_error": "sim_error" in info,
                              "object": env.scene.object_spec.name})
                final_obs[i] = obs
                self._returns[i], self._lengths[i] = 0, 0
                obs, _ = env.reset()
            obs_list.append(obs)
        return StepResult(stack_obs(obs_list), rewards, terminated, truncated, final_obs, stats, errors)
