"""`corn-drake bench cores`: what the machine itself allows N rollout workers, with no Ray and
no learner: the ceiling of `bench scale`'s efficiency.

For each process count N, N plain processes (multiprocessing, spawn)
each do exactly a Ray segment worker's job: build `--envs-per-worker` teacher envs (worker i's
envs, as the trainer numbers them) and a CPU copy of a randomly initialised policy with one
torch thread, then collect `--segments` PPO segments of `--rollout-steps` steps. Every
segment starts at a barrier, as every worker's segment starts when the learner sends the
update. Per count the report gives:

  pace_mean / pace_slowest   env steps/s of a process while it collects (inference included),
                             the mean over processes and segments, and the slowest process's;
  pace_ratio                 pace_mean / pace_mean of 1 process (same run): what
                             the other busy cores cost each one (shared caches, memory bandwidth,
                             clocks, sibling hyper-threads);
  lockstep_efficiency        per segment, (N x envs x steps / the slowest process's seconds) /
                             (N x the 1-process pace), averaged: the efficiency a lock-step
                             learner that cost nothing would get. bench scale's efficiency can
                             not be higher on this machine.

The processes are left where the kernel puts them (pinning each to a core was measured here and
retired: no difference that survived a rerun, docs/many_core.md); the report keeps its
`modes.unpinned` block so it reads as the earlier reports did. The report's `machine` block says
how many physical cores the usable CPUs are.
"""

from __future__ import annotations

import dataclasses

from corn_drake.arguments.value_types import nonnegative_int, positive_int
# the same list rules as bench scale's --workers
from corn_drake.bench.training.scale import (worker_counts)
from corn_drake.rl.policy_kinds import POLICY_KINDS

NAME = "cores"
HELP = ("the machine's own ceiling for N rollout workers (no Ray, no learner): each process's "
        "collection pace and the lock-step efficiency")


def add_arguments(parser):
    parser.add_argument("--procs", type=worker_counts, default="1,2",
                        help="comma-separated process counts, e.g. 1,8,15 (1, the baseline, is "
                             "measured even when left out)")
    parser.add_argument("--envs-per-worker", type=positive_int, default=8,
                        help="envs each process steps")
    parser.add_argument("--segments", type=positive_int, default=4,
                        help="segments timed per process")
    parser.add_argument("--warmup-segments", type=nonnegative_int, default=1,
                        help="segments collected first, untimed (first calls into torch and "
                             "the simulators)")
    parser.add_argument("--rollout-steps", type=positive_int, default=32,
                        help="steps per env and segment")
    parser.add_argument("--policy", default="corn", choices=POLICY_KINDS,
                        help="policy run (randomly initialised: timing only)")
    parser.add_argument("--task", default="push",
                        help="task overlay: a name in diagrams/tasks/ or a YAML file")
    parser.add_argument("--seed", type=nonnegative_int, default=0,
                        help="seed of the networks, the envs' episodes and the action noise")


@dataclasses.dataclass(frozen=True)
class Job:
    """What one process collects (picklable: it travels to a spawned process)."""
    policy: str
    task: str
    seed: int
    envs: int
    rollout_steps: int
    warmup: int
    segments: int


def collect_paces(job: Job, index: int, count: int, barrier, results) -> None:
    """Process body: worker `index` of `count` collects `job`'s segments and puts
    (index, [seconds per timed segment]) on `results`; ('error', index, text) on failure,
    so the parent reports it instead of waiting forever."""
    try:
        import time

        import numpy as np
        import torch

        from corn_drake.config.plumbing.diagram_files import load_teacher_config
        from corn_drake.rl.ppo.agent import TeacherAgent
        from corn_drake.rl.pretrained_encoders import make_encoder
        from corn_drake.rl.run_progress import run_env_factory
        from corn_drake.rl.ppo.segments import SegmentCollector
        from corn_drake.rl.envs.vec_env import EnvBatch

        torch.set_num_threads(1)  # as a segment worker runs
        torch.manual_seed(job.seed)
        env_cfg = load_teacher_config(job.task)
        factory = run_env_factory(env_cfg, job.seed, count, job.envs)
        agent = TeacherAgent(job.policy, make_encoder(job.policy))
        collector = SegmentCollector(EnvBatch(factory, job.envs, index * job.envs), agent, "cpu")
        rng = np.random.default_rng([job.seed, index])
        shape = (job.rollout_steps, job.envs, agent.log_std.shape[0])
        for _ in range(job.warmup):
            collector.collect(rng.standard_normal(shape).astype(np.float32))
        seconds = []
        for _ in range(job.segments):
            barrier.wait()  # every process's segment starts together, as after a broadcast
            started = time.perf_counter()
            collector.collect(rng.standard_normal(shape).astype(np.float32))
            seconds.append(time.perf_counter() - started)
        results.put((index, seconds))
    except BaseException as exc:  # noqa: BLE001 - reported by the parent, which then fails
        barrier.abort()
        results.put(("error", index, f"{type(exc).__name__}: {exc}"))


def measure(job: Job, count: int) -> dict:
    """`count` processes collecting `job` at once: each one's seconds per timed segment."""
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")  # no forked copy of a parent's Drake or torch
    barrier, results = ctx.Barrier(count), ctx.Queue()
    procs = [ctx.Process(target=collect_paces, args=(job, i, count, barrier, results),
                         daemon=True) for i in range(count)]
    for p in procs:
        p.start()
    try:
        rows = _gather(results, procs)
    finally:
        for p in procs:
            p.join(timeout=30)
            if p.is_alive():
                p.terminate()
    errors = [r for r in rows if r[0] == "error"]
    if errors:
        raise RuntimeError(f"bench cores: process {errors[0][1]} of {count} failed: "
                           f"{errors[0][2]}")
    rows.sort()
    return {"procs": count, "seconds": [r[1] for r in rows]}


def _gather(results, procs) -> list:
    """One row per process; a process that died without a row (a crash in native code) is
    reported instead of waited for."""
    import queue

    rows = []
    while len(rows) < len(procs):
        try:
            rows.append(results.get(timeout=5))
        except queue.Empty:
            reported = {r[1] if r[0] == "error" else r[0] for r in rows}
            dead = [i for i, p in enumerate(procs)
                    if p.exitcode not in (None, 0) and i not in reported]
            if dead:
                raise RuntimeError(f"bench cores: process {dead[0]} of {len(procs)} died "
                                   f"(exit code {procs[dead[0]].exitcode})") from None
    return rows


def summarise(run: dict, steps_per_segment: int, baseline_pace: float | None) -> dict:
    """Paces, ratio to the 1-process pace and the lock-step efficiency of one measured count."""
    import numpy as np

    seconds = np.asarray(run["seconds"])  # (procs, segments)
    paces = steps_per_segment / seconds
    per_process = paces.mean(axis=1)
    pace_mean = float(per_process.mean())
    baseline = pace_mean if baseline_pace is None else baseline_pace
    slowest = seconds.max(axis=0)  # per segment: the one a lock-step learner waits for
    return {**run,
            "pace_mean": pace_mean,
            "pace_slowest": float(per_process.min()),
            "pace_per_process": per_process.tolist(),
            "pace_ratio": pace_mean / baseline,
            "lockstep_efficiency": float(np.mean(steps_per_segment / slowest / baseline))}


def run(args) -> dict:
    from corn_drake.config.plumbing.diagram_files import load_teacher_config
    from corn_drake.nn.threads import usable_cpus

    load_teacher_config(args.task).check()  # a bad --task fails here, not in N processes
    job = Job(args.policy, args.task, args.seed, args.envs_per_worker, args.rollout_steps,
              args.warmup_segments, args.segments)
    counts = sorted(set(args.procs) | {1})
    steps = args.envs_per_worker * args.rollout_steps
    runs, baseline = [], None
    for count in counts:
        summary = summarise(measure(job, count), steps, baseline)
        baseline = summary["pace_mean"] if baseline is None else baseline
        runs.append(summary)
        print(f"  {count} processes: pace {summary['pace_mean']:.0f} env steps/s (slowest "
              f"{summary['pace_slowest']:.0f}), ratio {summary['pace_ratio']:.2f}, "
              f"lock-step efficiency {summary['lockstep_efficiency']:.2f}", flush=True)
    modes = {"unpinned": {
        "procs": counts,
        "pace_ratio": [r["pace_ratio"] for r in runs],
        "lockstep_efficiency": [r["lockstep_efficiency"] for r in runs],
        "pace_mean": [r["pace_mean"] for r in runs],
        "pace_slowest": [r["pace_slowest"] for r in runs],
        "runs": runs,
    }}
    cpus = usable_cpus()
    return {"procs": counts, "modes": modes, "policy": args.policy, "task": args.task,
            "envs_per_worker": args.envs_per_worker, "rollout_steps": args.rollout_steps,
            "segments": args.segments, "warmup_segments": args.warmup_segments,
            "usable_cpus": cpus,
            "warnings": [f"--procs {n}: more processes than the {cpus} usable cores"
                         for n in counts if n > cpus]}
