"""Running one episode of an env with a policy callable, optionally recorded to Meshcat HTML."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable

import numpy as np


@dataclasses.dataclass
class EpisodeResult:
    steps: int
    total_reward: float
    success: bool
    final_status: dict
    sim_error: str | None = None
    recording: Path | None = None


def run_episode(env, policy: Callable[[dict], np.ndarray], *, seed: int | None = None,
                max_steps: int | None = None, record_path: str | Path | None = None,
                on_reset: Callable[[dict], None] | None = None) -> EpisodeResult:
    """Resets `env`, steps `policy(obs)` until the episode ends (or max_steps)."""
    obs, info = env.reset(seed=seed)
    if on_reset is not None:
        on_reset(obs)
    if record_path is not None:
        env.start_recording()
    total, steps, status, error = 0.0, 0, info.get("status", {}), None
    limit = max_steps or env.cfg.task.episode_steps
    while steps < limit:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        total += reward
        steps += 1
        status = info.get("status", status)
        error = info.get("sim_error")
        if terminated or truncated:
            break
    recording = env.save_recording(record_path) if record_path is not None else None
    return EpisodeResult(steps=steps, total_reward=total, success=bool(status.get("success", 0) > 0),
                         final_status=status, sim_error=error, recording=recording)
