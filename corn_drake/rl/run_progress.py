"""What the teacher's PPO trainer (rl/training/ppo_trainer.py) and the student's DAgger
(rl/training/dagger.py) share: the env factory of a run, CPU copies of state for checkpoints, the progress (counters, curves,
RNG streams) a resumed run continues from, and per-object episode counts."""

from __future__ import annotations

import numpy as np
import torch

from corn_drake.rl.envs.vec_env import EnvFactory


def run_env_factory(env_config, seed: int, workers: int, envs_per_worker: int,
                    start_episode: int = 0, primitive=None) -> EnvFactory:
    """The recipe of a run's envs: all its workers' envs (at least one worker's) share the
    object rounds, starting at `start_episode`."""
    return EnvFactory(env_config, seed, num_envs=max(workers, 1) * envs_per_worker,
                      start_episode=start_episode, primitive=primitive)


def to_cpu(state):
    """`state` (nested dicts / lists / tuples of tensors and plain values) with every tensor
    moved to the CPU."""
    if isinstance(state, torch.Tensor):
        return state.cpu()
    if isinstance(state, dict):
        moved = type(state)((k, to_cpu(v)) for k, v in state.items())
        if hasattr(state, "_metadata"):  # a module state_dict's version record, used on load
            moved._metadata = state._metadata
        return moved
    if isinstance(state, (list, tuple)):
        return type(state)(to_cpu(v) for v in state)
    return state


# The run's progress every trainer keeps on the trainer object itself and in its checkpoint.
PROGRESS_FIELDS = ("global_step", "update_index", "history", "recent_episodes",
                   "episodes_per_object")


def progress_state(run) -> dict:
    """What a checkpoint holds of `run`'s progress (a PPO Trainer or a DaggerTrainer): its
    counters, history, recent episodes, per-object counts and the random streams it draws from
    (`run.generator`, `run.np_rng`, torch's global one). restore_progress reads it back."""
    from corn_drake.rl.checkpoints import env_hash

    return {**{name: getattr(run, name) for name in PROGRESS_FIELDS},
            "torch_rng": torch.get_rng_state(), "generator": run.generator.get_state(),
            "np_rng": run.np_rng.bit_generator.state, "env_sha256": env_hash(run.cfg)}


def restore_progress(run, state: dict) -> None:
    run.global_step, run.update_index = state["global_step"], state["update_index"]
    run.history = state["history"]
    # Absent in checkpoints of teacher runs written before they were kept.
    run.recent_episodes = state.get("recent_episodes", [])
    run.episodes_per_object = state.get("episodes_per_object", {})
    torch.set_rng_state(state["torch_rng"])
    run.generator.set_state(state["generator"])
    run.np_rng.bit_generator.state = state["np_rng"]


def count_episodes_per_object(counts: dict[str, int], episodes: list[dict]) -> None:
    """Adds finished episodes (EnvBatch episode stats) to `counts`, object id -> episodes."""
    for episode in episodes:
        counts[episode["object"]] = counts.get(episode["object"], 0) + 1


def recent_mean(episodes: list[dict], key: str) -> float:
    """Mean of `key` over the episodes that have it (0.0 when none has: nothing finished yet)."""
    values = [e[key] for e in episodes if key in e]
    return float(np.mean(values)) if values else 0.0
