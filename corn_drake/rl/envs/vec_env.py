"""Batches of envs (TeacherEnvs, or StudentEnvs for a student config) stepped together,
in-process (EnvBatch) or on Ray actors (ray_workers).

Auto-reset: an env whose episode ended is reset inside `step`; the returned observation is the new
episode's first one, and `final_obs` keeps the last observation of the old episode (the learner
bootstraps time-outs from its value).

Episodes are numbered per env; env i's episode k is fully determined by (factory seed, i, k):
its object (EnvFactory.object_for) and the seed its reset draws everything else from.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
from typing import Any

import numpy as np

from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.config.student import StudentDiagramConfig
from corn_drake.errors import InputError

# StudentEnv's tracking errors (info["tracking"]) whose episode means join the episode stats
# as mean_<name>.
TRACKING_STATS = ("translation_error_m", "rotation_error_deg")


def cycle_object(ids: list[str], seed: int, index: int, episode: int, num_envs: int) -> str:
    """Env `index`'s object for its `episode`-th episode.

    Each env walks the objects in rounds of len(ids) episodes: round r is one seeded shuffle of
    all ids, shared by the envs, and env i enters it at offset i * len(ids) / num_envs. So every
    env trains on every object once per round, and envs at the same episode count hold
    different objects (while num_envs <= len(ids)), whatever the number of envs.
    """
    if not 0 <= index < num_envs:
        raise ValueError(f"env index {index} is outside the {num_envs} envs sharing the objects "
                         "(EnvFactory.num_envs)")
    n = len(ids)
    round_, step = divmod(episode, n)
    offset = (index * n) // num_envs
    order = np.random.default_rng([seed, round_]).permutation(n)
    return ids[order[(offset + step) % n]]


def library_train_ids(library: str) -> list[str]:
    """The train objects of an object library, each loaded and checked (its files exist and
    load, mass, inertia and poses are usable), so a broken object is named before a run writes
    anything instead of when its turn comes, hours in; no train object is an error too."""
    from corn_drake.assets.library import list_objects, load_object_spec

    ids = list_objects(library, "train")
    if not ids:
        from corn_drake.assets.manifest import read_manifest

        held = [o.id for o in read_manifest(library).objects]
        hint = (f" (its {len(held)} objects are all unseen; an ingested folder of a few meshes "
                "has no train ones): train on one of them with --set "
                "scene.object.library_objects=one --set scene.object.object_id="
                f"{held[0]}, or evaluate them with `evaluate --split all`") if held else ""
        raise InputError(f"object library {library} has no train objects{hint}")
    for object_id in ids:
        load_object_spec(library, object_id)
    return ids


@dataclasses.dataclass
class EnvFactory:
    """Picklable recipe for the envs of one batch: the config, and seeds derived from `seed`.

    With an object config naming every train object of a library (library_objects: train),
    envs move through them, a new one every episode (cycle_object); one library object (or a
    primitive) stays for the whole run. Another object needs another diagram (the
    geometry lives in it). Building one took 15-25 ms here against 0.6-1.7 s of simulation per
    300-step episode (2-5.5 ms per step), for library objects of 1-16 hulls: cheap enough to
    switch every episode. But pydrake never frees a diagram holding Python systems (Drake
    1.51: +2.3 MB RSS per discarded TeacherEnv, 463 rebuilds +1.2 GB), so EnvBatch keeps the
    envs it built in a pool by object and reuses them: about one env per object per batch,
    built once (32 envs over 69 objects built 80, +410 MiB), and a switch later costs no more
    than a reset.
    """

    # A StudentDiagramConfig makes StudentEnvs (observations {"student", "teacher"}); the
    # object and seed settings are its teacher part's.
    config: TeacherDiagramConfig | StudentDiagramConfig
    seed: int = 0
    # Envs sharing the object rounds (all workers' together), to spread their starting offsets;
    # 0: EnvBatch / RayEnvBatch fill in their own total.
    num_envs: int = 0
    # Episode number every env starts at: a resumed run continues the object rounds and the
    # episode seeds from about where it stopped instead of replaying its first episodes.
    start_episode: int = 0
    # A PrimitiveConfig makes PrimitiveEnvs (one step = one contact primitive,
    # rl/envs/primitive_env.py) of the teacher config instead of TeacherEnvs.
    primitive: Any = None

    @property
    def teacher_config(self) -> TeacherDiagramConfig:
        """The teacher diagram's config (a student config's teacher part)."""
        if isinstance(self.config, StudentDiagramConfig):
            return self.config.teacher
        return self.config

    @functools.cached_property
    def train_objects(self) -> list[str] | None:
        """The train ids the envs cycle through; None when the config fixes one object."""
        obj = self.teacher_config.scene.object
        return library_train_ids(obj.library) if obj.cycles_library else None

    def object_for(self, index: int, episode: int) -> str | None:
        """Env `index`'s object id in its `episode`-th episode (None: the config's object)."""
        ids = self.train_objects
        if ids is None:
            return None
        return cycle_object(ids, self.seed, index, episode, self.num_envs)

    def episode_seed(self, index: int, episode: int) -> int:
        return int(np.random.SeedSequence([self.seed, index, episode]).generate_state(1)[0])

    def make(self, index: int, episode: int = 0):
        from corn_drake.rl.envs.teacher_env import TeacherEnv
        from corn_drake.rl.envs.student_env import StudentEnv

        cfg = copy.deepcopy(self.config)
        student = isinstance(cfg, StudentDiagramConfig)
        teacher_cfg = cfg.teacher if student else cfg
        object_id = self.object_for(index, episode)
        if object_id is None:
            teacher_cfg.seed = self.seed + index
        else:
            # Pooled envs run any env's episodes of their object: the build (its cloud subset)
            # depends on the object only, so which env built it changes nothing.
            teacher_cfg.seed = self.seed
            teacher_cfg.scene.object.library_objects = "one"
            teacher_cfg.scene.object.object_id = object_id
        if self.primitive is not None:
            from corn_drake.rl.envs.primitive_env import PrimitiveEnv

            return PrimitiveEnv(cfg, self.primitive)
        return StudentEnv(cfg) if student else TeacherEnv(cfg)


def stack_obs(observations: list[dict]) -> dict:
    """One array per key (nested dicts, as a StudentEnv's, stay nested), envs along axis 0."""
    return {k: stack_obs([o[k] for o in observations]) if isinstance(observations[0][k], dict)
            else np.stack([o[k] for o in observations]) for k in observations[0]}


def concat_obs(parts: list[dict]) -> dict:
    """Batched observations (stack_obs's) joined along axis 0, nested dicts kept."""
    return {k: concat_obs([p[k] for p in parts]) if isinstance(parts[0][k], dict)
            else np.concatenate([p[k] for p in parts]) for k in parts[0]}


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
        if not factory.num_envs:
            factory = dataclasses.replace(factory, num_envs=first_index + num_envs)
        self.factory = factory
        self.indices = list(range(first_index, first_index + num_envs))
        self._episodes = [factory.start_episode] * num_envs  # each env's current episode number
        self._objects = [factory.object_for(i, factory.start_episode) for i in self.indices]
        self.envs = [factory.make(i, factory.start_episode) for i in self.indices]
        self._idle: dict[str | None, list] = {}  # built envs not in use, by object id
        self.built = num_envs  # envs built so far (the pool's size plus the envs in use)
        self._returns = np.zeros(num_envs)
        self._lengths = np.zeros(num_envs, dtype=int)
        # StudentEnvs' tracking error (info["tracking"]), summed over each episode's steps, and
        # the count of steps that reported it (last column): info does not leave the batch, so
        # its episode means travel in the episode stats.
        self._tracking = np.zeros((num_envs, len(TRACKING_STATS) + 1))

    def __len__(self) -> int:
        return len(self.envs)

    def _begin_episode(self, slot: int) -> dict[str, np.ndarray]:
        """Resets env `slot` into its current episode, after swapping in an env of the
        episode's object (from the pool, or built) if its object changes."""
        index, episode = self.indices[slot], self._episodes[slot]
        object_id = self.factory.object_for(index, episode)
        if object_id != self._objects[slot]:
            self._idle.setdefault(self._objects[slot], []).append(self.envs[slot])
            idle = self._idle.get(object_id)
            if idle:
                self.envs[slot] = idle.pop()
            else:
                self.envs[slot] = self.factory.make(index, episode)
                self.built += 1
            self._objects[slot] = object_id
        obs, _ = self.envs[slot].reset(seed=self.factory.episode_seed(index, episode))
        return obs

    def reset(self) -> dict[str, np.ndarray]:
        """Restarts every env's current episode from its beginning."""
        self._returns[:] = 0
        self._lengths[:] = 0
        self._tracking[:] = 0
        return stack_obs([self._begin_episode(slot) for slot in range(len(self.envs))])

    def step(self, actions: np.ndarray) -> StepResult:
        if len(actions) != len(self.envs):
            raise ValueError(f"actions: expected one row per env ({len(self.envs)}), got {len(actions)}")
        obs_list, rewards = [], np.zeros(len(self.envs))
        terminated = np.zeros(len(self.envs), bool)
        truncated = np.zeros(len(self.envs), bool)
        final_obs, stats, errors = {}, [], 0
        for i, action in enumerate(actions):
            env = self.envs[i]
            obs, reward, term, trunc, info = env.step(action)
            rewards[i], terminated[i], truncated[i] = reward, term, trunc
            self._returns[i] += reward
            self._lengths[i] += 1
            if "sim_error" in info:
                errors += 1
            if "tracking" in info:
                self._tracking[i] += [*(info["tracking"][k] for k in TRACKING_STATS), 1]
            if term or trunc:
                status = info.get("status", {})
                stats.append({"return": self._returns[i], "length": int(self._lengths[i]),
                              "success": float(status.get("success", 0.0)),
                              "sim_error": "sim_error" in info,
                              "object": env.scene.object_spec.name})
                *sums, count = self._tracking[i]
                if count:
                    stats[-1].update({f"mean_{k}": float(v / count)
                                      for k, v in zip(TRACKING_STATS, sums)})
                final_obs[i] = obs
                self._returns[i], self._lengths[i] = 0, 0
                self._tracking[i] = 0
                self._episodes[i] += 1
                obs = self._begin_episode(i)  # object switches happen here: timed as steps
            obs_list.append(obs)
        return StepResult(stack_obs(obs_list), rewards, terminated, truncated, final_obs, stats, errors)
