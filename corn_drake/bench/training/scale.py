"""`corn-drake bench scale`: training steps/s of the Ray path at each worker count, and efficiency.

For each worker count W the real trainer (corn_drake/rl/training/ppo_trainer.py) trains with W
Ray rollout workers of --envs-per-worker envs each (weak scaling: the batch grows with W), each worker
stepping its own envs for the whole rollout segment with a CPU copy of the policy
(rl/workers/segment_workers.py), the learner's PPO update on --device, a randomly initialised encoder
(timing only). Rates are measured on the timed updates only (bench/training/timed_training.py).
efficiency(W) = (steps/s at W / W) / (steps/s at 1 worker): 1.0 is perfect scale-out. The
1-worker run is the baseline, measured even when --workers leaves it out (the report then says
`baseline_added`). The same envs are also trained in this process (`train --workers 0`) in the
same run: `in_process_steps_per_s`, and `ray_1_worker_vs_in_process` = the 1-worker rate over
it (what moving the envs into a worker costs end to end).

Where each run's time goes (the learner's wall time per update, fractions adding up to 1):
  rollout_wait     the collectors' collect(): dispatch, the slowest worker's segment (its
                   inference and env steps), the transfer back (in-process: the collection);
  learner_rollout  the rest of the rollout on the learner: the update's noise draws, the weight
                   broadcast, the reward scaler, the rollout tensors;
  ppo_update       PPO.update;
  other            the rest of the update (GAE).
learner_share = 1 - rollout_wait share: the time the workers idle waiting for the learner (PPO
stays on-policy: a segment needs the weights of the update before it).
env_steps_per_s_per_worker is each worker's own pace while it collects (its envs x steps / its
collect() seconds, inference included; mean over workers and timed updates), and
worker_pace_ratio = that pace / the pace of the same envs collected by the same policy in this
process (in_process_env_steps_per_s, the in-process run's collector): what being a Ray worker
costs a worker (1.0: nothing). worker_inference_share is the part of a worker's collect() its
policy's forward passes take. rollout_wait_s_per_update against slowest_collection_s_per_update
splits the learner's wait into the slowest worker's own collection and the rest (dispatch,
transfer, unpacking).

Each run starts its own local Ray and shuts it down after (rl/workers/ray_workers.init_ray ends what
Ray leaves behind), unless Ray was already running in this process: then that one is used.
With --ray-address each run joins that Ray cluster instead (its workers one CPU each, SPREAD
over the nodes: rl/workers/cluster.py) and leaves it running; the learner and the in-process
run stay in this process. Every row names the Ray nodes its workers ran on: `worker_nodes`
(each worker's node id, as metrics.json) and `nodes` (how many distinct), and the report's
top-level `nodes` / `worker_nodes` lists give them per worker count (the distinct node ids,
sorted), beside `steps_per_s` and `efficiency`.
"""

from __future__ import annotations

import argparse

from corn_drake.bench.training.timed_training import COLLECT, PPO_UPDATE, add_trainer_arguments
from corn_drake.arguments.value_types import positive_int, positive_int_list

NAME = "scale"
HELP = "training steps/s with 1, 2, 4, ... Ray rollout workers, and the efficiency per worker"

ROLLOUT_WAIT = "rollout_wait"
LEARNER_ROLLOUT = "learner_rollout"
FRACTION_KEYS = (ROLLOUT_WAIT, LEARNER_ROLLOUT, "ppo_update", "other")


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
    parser.add_argument("--ray-address", default=None, metavar="ADDRESS",
                        help="run each worker count's workers on the Ray cluster at ADDRESS "
                             "(HOST:PORT of its head, as `ray start --head` printed it); the "
                             "learner stays in this process (default: a local Ray per run)")


def instrument_rollouts(trainer, timer, segments: list) -> None:
    """Times the learner's wait on this trainer's collectors (their collect()) and keeps the
    segments of the timed updates (the workers' own seconds are in them)."""
    original = trainer.rollouts.collect

    def collect(noise):
        with timer.phase(ROLLOUT_WAIT):
            segment = original(noise)
        if timer.in_window:
            segments.append(segment)
        return segment

    trainer.rollouts.collect = collect


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


def slowest_collection_s(segments: list) -> float:
    """Mean over the timed updates of the slowest collector's own collect() seconds: the part
    of the learner's wait the workers' pace explains (the rest: dispatch, transfer, unpacking)."""
    import numpy as np

    return float(np.mean([max(p["total"] for p in segment.parts) for segment in segments]))


def worker_paces(segments: list, rollout_steps: int) -> tuple[float, float]:
    """(mean env steps/s of a collector while it collects, mean share of its collect() in
    inference) over every collector of every segment."""
    import numpy as np

    parts = [p for segment in segments for p in segment.parts]
    return (float(np.mean([p["envs"] * rollout_steps / p["total"] for p in parts])),
            float(np.mean([p["inference"] / p["total"] for p in parts])))


def measure(args, env_cfg, workers: int) -> dict:
    """One run with `workers` Ray workers (0: the envs in this process): its rate and where the
    learner's time goes."""
    from corn_drake.bench.phases import PhaseTimer
    from corn_drake.bench.training.timed_training import (check_counts, run_trainer, train_config,
                                                 trainer_logged_steps_per_s)

    cfg = train_config(args, env_cfg, workers, args.envs_per_worker, args.device)
    cfg.ray_address = args.ray_address or ""
    timer, segments = PhaseTimer(), []
    with _RaySession():
        trainer, metrics = run_trainer(cfg, timer, args.warmup_updates,
                                       instrument=lambda t: instrument_rollouts(t, timer,
                                                                                segments))
        restarts = getattr(trainer.rollouts, "restarts", 0)
        del trainer  # its actors go with the session
    check_counts(timer, {timer.WINDOW: args.updates, ROLLOUT_WAIT: args.updates})
    per_update = max(workers, 1) * args.envs_per_worker * args.rollout_steps
    steps = per_update * args.updates
    s, total = timer.seconds, timer.window_seconds
    seconds = {ROLLOUT_WAIT: s[ROLLOUT_WAIT], LEARNER_ROLLOUT: s[COLLECT],
               "ppo_update": s[PPO_UPDATE], "other": s[timer.WINDOW]}
    history = metrics["history"][args.warmup_updates:]  # the timed updates
    pace, inference_share = worker_paces(segments, args.rollout_steps)
    worker_nodes = metrics.get("worker_nodes", [])  # each Ray worker's node id (none: in process)
    return {
        "workers": workers,
        "envs": max(workers, 1) * args.envs_per_worker,
        "steps": steps,
        "steps_per_s": steps / total,
        "learner_share": 1.0 - seconds[ROLLOUT_WAIT] / total,
        "env_steps_per_s_per_worker": pace,
        "worker_inference_share": inference_share,
        # Per update: the learner's wait for the segments, and the slowest collector's own time.
        "rollout_wait_s_per_update": seconds[ROLLOUT_WAIT] / args.updates,
        "slowest_collection_s_per_update": slowest_collection_s(segments),
        "time_fractions": {k: v / total for k, v in seconds.items()},
        "time_s": {**seconds, "total": total},
        "trainer_logged_steps_per_s": trainer_logged_steps_per_s(history, per_update),
        "episodes_finished": sum(r["episodes"] for r in history),
        "sim_errors": sum(r["sim_errors"] for r in history),
        "worker_restarts": restarts,
        "worker_nodes": worker_nodes,
        "nodes": len(set(worker_nodes)),
        "driver_node": metrics.get("driver_node"),
    }


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
    from corn_drake.config.plumbing.diagram_files import load_teacher_config

    device = training_device(args.device, "--device")  # before any env or Ray starts
    if args.ray_address:  # before any run: ray.init retries an address for minutes
        from corn_drake.rl.workers.cluster import check_ray_address

        check_ray_address(args.ray_address, "--ray-address")
    env_cfg = load_teacher_config(args.task)
    env_cfg.check()
    cpus = usable_cpus()
    counts = sorted(set(args.workers) | {1})  # 1 first: the baseline
    # On a cluster the workers take the nodes' CPUs (`ray start --num-cpus`; too few: the run
    # stops with one line), not this machine's.
    warnings = [] if args.ray_address else oversubscription_warnings(counts, cpus)
    for line in warnings:
        print(f"warning: {line}", file=sys.stderr)
    runs = []
    with torch_threads(args.torch_threads):
        threads_used = torch.get_num_threads()
        # The same envs trained in this process: the baseline of the workers' pace and of the
        # 1-worker run's end-to-end rate.
        local = measure(args, env_cfg, 0)
        print(f"  in process: {local['steps_per_s']:.0f} steps/s", flush=True)
        for workers in counts:
            runs.append(measure(args, env_cfg, workers))
            nodes = runs[-1].get("nodes", 1)
            where = f" on {nodes} node{'s' * (nodes != 1)}" if args.ray_address else ""
            print(f"  {workers} workers{where}: {runs[-1]['steps_per_s']:.0f} steps/s, "
                  f"learner share "
                  f"{runs[-1]['learner_share']:.2f}, worker pace "
                  f"{runs[-1]['env_steps_per_s_per_worker']:.0f} env steps/s", flush=True)
    in_process = local["env_steps_per_s_per_worker"]
    baseline = runs[0]["steps_per_s"]
    efficiency = [r["steps_per_s"] / r["workers"] / baseline for r in runs]
    for r, e in zip(runs, efficiency):
        r["efficiency"] = e
    # Each worker's own pace while collecting against the in-process collection of the same envs
    # and policy: what being a Ray worker costs a worker (1.0: nothing).
    pace = [r["env_steps_per_s_per_worker"] / in_process for r in runs]
    return {
        "workers": counts,
        "efficiency": efficiency,
        "steps_per_s": [r["steps_per_s"] for r in runs],
        "learner_share": [r["learner_share"] for r in runs],
        "worker_pace_ratio": pace,
        "in_process_env_steps_per_s": in_process,
        "in_process_steps_per_s": local["steps_per_s"],
        "ray_1_worker_vs_in_process": baseline / local["steps_per_s"],
        "in_process_run": local,
        "baseline_steps_per_s": baseline,
        "requested_workers": args.workers,
        # True when --workers left out 1: its run was added as the baseline.
        "baseline_added": 1 not in args.workers,
        "runs": runs,
        # Per worker count: how many Ray nodes its workers ran on, and which (sorted node ids).
        "nodes": [r.get("nodes", 1) for r in runs],
        "worker_nodes": [sorted(set(r.get("worker_nodes", []))) for r in runs],
        "ray_address": args.ray_address,
        "driver_node": runs[-1].get("driver_node"),
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
