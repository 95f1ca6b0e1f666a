"""`corn-drake bench scale`: training steps/s of the Ray path at each worker count, and efficiency.

For each worker count W the real trainer (corn_drake/rl/trainer.py) trains with W Ray rollout
workers of --envs-per-worker envs each (weak scaling: the batch grows with W), the learner's
batched inference and PPO update in the loop, a randomly initialised encoder (timing only), on
--device. Rates are measured on the timed updates only (bench/timed_training.py).
efficiency(W) = (steps/s at W / W) / (steps/s at 1 worker): 1.0 is perfect scale-out (issue 14
asks >= 0.75 at 8 workers on a 16-core machine). The 1-worker run is the baseline, measured
even when --workers leaves it out (the report then says `baseline_added`).

Why a run does not scale shows in the learner's share of its time. The trainer steps all
workers in lock step: the learner sends actions, waits for every worker's step, then runs
inference for all envs, and the workers idle while it does that and the PPO update. Per run:
  env_step_wait     RayEnvBatch.step: dispatch, the slowest worker's step, transfer, stacking;
  policy_inference  the rest of the rollout: observation tensors, encoder and action sampling
                    for all envs at once, value bootstraps, the reward scaler, buffers;
  ppo_update        PPO.update;
  other             the rest of the update (stacking the rollout, GAE).
learner_share = 1 - env_step_wait share. env_steps_per_s_per_worker (steps / env_step_wait / W)
is the workers' own pace while stepping: flat across W with falling efficiency means the learner
limits; falling too means the workers contend for cores (or memory bandwidth).
worker_pace_ratio = that pace / the pace of the same --envs-per-worker envs stepped in this
process with random actions (in_process_env_steps_per_s, measured in the same run): what the
lock-step round trips cost a worker.

Each run starts its own local Ray and shuts it down after (rl/ray_workers.init_ray ends what
Ray leaves behind), unless Ray was already running in this process: then that one is used.
"""

from __future__ import annotations

import argparse

from corn_drake.bench.timed_training import COLLECT, PPO_UPDATE, add_trainer_arguments
from corn_drake.arguments.value_types import positive_int, positive_int_list

NAME = "scale"
HELP = "training steps/s with 1, 2, 4, ... Ray rollout workers, and the efficiency per worker"

ENV_STEP_WAIT = "env_step_wait"
FRACTION_KEYS = (ENV_STEP_WAIT, "policy_inference", "ppo_update", "other")


def worker_counts(text: str) -> list[int]:
    """'1,2,4' -> [1, 2, 4]: integers >= 1, each once (argparse type: errors name --workers)."""
    counts = positive_int_list(text)
    repeated = sorted({c for c in counts if counts.count(c) > 1})
    if repeated:
        raise argparse.ArgumentTypeError(
            f"each worker count once, got {', '.join(map(str, repeated))} more than once in "
            f"{text!r}")
    return counts


def add_arguments(parser):
    add_trainer_arguments(parser)
    parser.add_argument("--workers", type=worker_counts, default="1,2",
                        help="comma-separated Ray worker counts, e.g. 1,2,4,8,15 (1, the "
                             "baseline, is measured even when left out)")
    parser.add_argument("--envs-per-worker", type=positive_int, default=8,
                        help="envs each worker steps (the learner batches inference over all)")
    parser.add_argument("--device", default="cpu",
                        help="torch device of the learner (agent, batched inference, PPO "
                             "update): cpu, cuda or cuda:N; the envs run on the CPU")


def instrument_ray(trainer, timer) -> None:
    """Times the learner's wait on the workers: RayEnvBatch.step of this trainer only."""
    timer.wrap(trainer.envs, "step", ENV_STEP_WAIT)


class _RaySession:
    """A local Ray for one run, shut down after it; a Ray this process already had is left
    running (and used)."""

    def __enter__(self):
        import ray

        self.owned = not ray.is_initialized()
        return self

    def __exit__(self, *exc):
        import ray

        if self.owned and ray.is_initialized():
            ray.shutdown()
        return False


def measure(args, env_cfg, workers: int) -> dict:
    """One run with `workers` Ray workers: its rate and where the learner's time goes."""
    from corn_drake.bench.phases import PhaseTimer
    from corn_drake.bench.timed_training import (check_counts, run_trainer, train_config,
                                                 trainer_logged_steps_per_s)

    cfg = train_config(args, env_cfg, workers, args.envs_per_worker, args.device)
    timer = PhaseTimer()
    with _RaySession():
        trainer, metrics = run_trainer(cfg, timer, args.warmup_updates,
                                       instrument=lambda t: instrument_ray(t, timer))
        restarts = trainer.envs.restarts
        del trainer  # its actors go with the session
    check_counts(timer, {timer.WINDOW: args.updates,
                         ENV_STEP_WAIT: args.updates * args.rollout_steps})
    per_update = workers * args.envs_per_worker * args.rollout_steps
    steps = per_update * args.updates
    s, total = timer.seconds, timer.window_seconds
    seconds = {ENV_STEP_WAIT: s[ENV_STEP_WAIT], "policy_inference": s[COLLECT],
               "ppo_update": s[PPO_UPDATE], "other": s[timer.WINDOW]}
    history = metrics["history"][args.warmup_updates:]  # the timed updates
    return {
        "workers": workers,
        "envs": workers * args.envs_per_worker,
        "steps": steps,
        "steps_per_s": steps / total,
        "learner_share": 1.0 - seconds[ENV_STEP_WAIT] / total,
        "env_steps_per_s_per_worker": steps / seconds[ENV_STEP_WAIT] / workers,
        "time_fractions": {k: v / total for k, v in seconds.items()},
        "time_s": {**seconds, "total": total},
        "trainer_logged_steps_per_s": trainer_logged_steps_per_s(history, per_update),
        "episodes_finished": sum(r["episodes"] for r in history),
        "sim_errors": sum(r["sim_errors"] for r in history),
        "worker_restarts": restarts,
    }


def in_process_env_steps_per_s(env_cfg, envs: int, steps: int, seed: int = 0) -> float:
    """Env steps/s (steps x envs) of `envs` envs stepped in this process with random actions:
    the pace a worker's envs have with nothing between their steps, the baseline of
    worker_pace_ratio."""
    import time

    import numpy as np

    from corn_drake.contract import ACTION_DIM
    from corn_drake.rl.vec_env import EnvBatch, EnvFactory

    batch = EnvBatch(EnvFactory(env_cfg, seed=seed), envs)
    rng = np.random.default_rng(seed)
    batch.reset()
    batch.step(rng.uniform(-1, 1, (envs, ACTION_DIM)))  # warm-up: first-step caches
    t0 = time.perf_counter()
    for _ in range(steps):
        batch.step(rng.uniform(-1, 1, (envs, ACTION_DIM)))
    return steps * envs / (time.perf_counter() - t0)


def oversubscription_warnings(counts: list[int], usable_cpus: int) -> list[str]:
    """One line per worker count whose workers plus the learner need more cores than this
    process may use: their efficiency then measures the machine, not the code."""
    return [f"--workers {w}: {w} workers and the learner need {w + 1} cores, this process may "
            f"use {usable_cpus}; the efficiency at {w} measures the shortage of cores"
            for w in counts if w + 1 > usable_cpus]


def device_name(device) -> str:
    import platform

    import torch

    if device.type == "cuda":
        return torch.cuda.get_device_name(device)
    return platform.processor() or platform.machine()


def run(args) -> dict:
    import sys

    import torch

    from corn_drake.nn.threads import torch_threads, usable_cpus
    from corn_drake.rl.device import training_device
    from corn_drake.config.diagram_files import load_teacher_config

    device = training_device(args.device, "--device")  # before any env or Ray starts
    env_cfg = load_teacher_config(args.task)
    env_cfg.check()
    cpus = usable_cpus()
    counts = sorted(set(args.workers) | {1})  # 1 first: the baseline
    warnings = oversubscription_warnings(counts, cpus)
    for line in warnings:
        print(f"warning: {line}", file=sys.stderr)
    runs = []
    with torch_threads(args.torch_threads):
        threads_used = torch.get_num_threads()
        for workers in counts:
            runs.append(measure(args, env_cfg, workers))
            print(f"  {workers} workers: {runs[-1]['steps_per_s']:.0f} steps/s, learner share "
                  f"{runs[-1]['learner_share']:.2f}", flush=True)
        # The same envs stepped in this process, as many steps as a worker takes per run.
        in_process = in_process_env_steps_per_s(env_cfg, args.envs_per_worker,
                                                args.updates * args.rollout_steps)
    baseline = runs[0]["steps_per_s"]
    efficiency = [r["steps_per_s"] / r["workers"] / baseline for r in runs]
    for r, e in zip(runs, efficiency):
        r["efficiency"] = e
    # Each worker's own pace while stepping against the in-process pace of the same envs: what
    # the round trips and the lock step cost a worker (1.0: nothing).
    pace = [r["env_steps_per_s_per_worker"] / in_process for r in runs]
    return {
        "workers": counts,
        "efficiency": efficiency,
        "steps_per_s": [r["steps_per_s"] for r in runs],
        "learner_share": [r["learner_share"] for r in runs],
        "worker_pace_ratio": pace,
        "in_process_env_steps_per_s": in_process,
        "baseline_steps_per_s": baseline,
        "requested_workers": args.workers,
        # True when --workers left out 1: its run was added as the baseline.
        "baseline_added": 1 not in args.workers,
        "runs": runs,
        "policy": args.policy,
        "task": env_cfg.task.name,
        "envs_per_worker": args.envs_per_worker,
        "updates": args.updates,
        "warmup_updates": args.warmup_updates,
        "rollout_steps": args.rollout_steps,
        "device": str(device),
        "device_name": device_name(device),
        "usable_cpus": cpus,
        "torch_threads": threads_used,
        "torch_interop_threads": torch.get_num_interop_threads(),
        "torch_version": torch.__version__,
        "warnings": warnings,
    }
