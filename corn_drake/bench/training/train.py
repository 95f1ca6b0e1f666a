"""`corn-drake bench train`: training steps/s of the real PPO trainer vs bare physics, same run.

The trainer (corn_drake/rl/training/ppo_trainer.py, in-process envs, the push task by default, a
randomly initialised encoder) runs a few updates; then the bare plant of the same scene is driven by
recorded torques exactly as `bench sim` does it (bench/bare_physics.py bare_physics_rate), on
one of the trainer's own envs. `train_ratio` = train / bare is the fraction of the physics-only
speed that training keeps (issue 14 asks >= 0.8).

Rates and shares are measured on the timed updates only, after --warmup-updates untimed ones
(bench/training/timed_training.py: the windows, and why), the trainer's own steps_per_s reported beside
them; the timers below go on this run's instances (bench/phases.py):
  physics           the bare plant's time for the policy steps simulated (same-run bare rate
                    x steps; capped at the time in Simulator.AdvanceTo, which it is part of).
                    The Python systems' callbacks run inside AdvanceTo and cannot be timed apart
                    from the plant's update without instrumenting every system, so the bare
                    replay is what separates them. So this share equals train_ratio (unless
                    capped): both say how much of the time is spent on physics;
  python_systems    the rest of AdvanceTo, plus EnvBatch.step outside it (action checks, the
                    observation / reward / status port evaluations, stacking);
  policy_inference  the rollout outside EnvBatch.step: observation tensors, cached encoder
                    features, action sampling, value bootstraps, the reward scaler, buffers;
  ppo_update        PPO.update (every epoch and minibatch);
  object_switching  env resets when episodes end, with the swap to another object's env;
  other             the rest of the update: stacking the rollout, GAE.
"""

from __future__ import annotations

from corn_drake.bench.training.timed_training import COLLECT, PPO_UPDATE, add_trainer_arguments
from corn_drake.arguments.renamed import add_renamed
from corn_drake.arguments.value_types import positive_int

NAME = "train"
HELP = "PPO training steps/s vs bare physics of the same scene, with where the time goes"

FRACTION_KEYS = ("physics", "python_systems", "policy_inference", "ppo_update",
                 "object_switching", "other")


def add_arguments(parser):
    add_trainer_arguments(parser)
    parser.add_argument("--envs-per-worker", type=positive_int, default=32,
                        help="envs, stepped in this process (as `train --workers 0 "
                             "--envs-per-worker N`)")
    add_renamed(parser, "--envs", "--envs-per-worker", " (as in `train`)")
    parser.add_argument("--bare-steps", type=positive_int, default=300,
                        help="policy steps of the bare-physics replay")


def instrument_envs(trainer, timer) -> None:
    """Timers on this trainer's env batch and envs (instances only), inside the update windows
    of timed_training.time_updates."""
    from corn_drake.bench.phases import time_simulator

    batch = trainer.envs
    original_begin = batch._begin_episode

    def begin_episode(slot):
        with timer.phase("object_switching"):
            obs = original_begin(slot)
        time_simulator(batch.envs[slot], timer, "advance")  # an env swapped in is timed too
        return obs

    batch._begin_episode = begin_episode
    timer.wrap(batch, "step", "env_step")
    for env in batch.envs:
        time_simulator(env, timer, "advance")


def breakdown(timer, bare_rate: float) -> tuple[dict, dict]:
    """(fractions of the windows' time, seconds per phase) from the timer of a finished run."""
    s = timer.seconds
    policy_steps = timer.calls["advance"]
    physics = min(policy_steps / bare_rate, s["advance"])
    seconds = {
        "physics": physics,
        "python_systems": s["advance"] - physics + s["env_step"],
        "policy_inference": s[COLLECT],
        "ppo_update": s[PPO_UPDATE],
        "object_switching": s["object_switching"],
        "other": s[timer.WINDOW],
    }
    total = timer.window_seconds
    return {k: v / total for k, v in seconds.items()}, {
        **seconds, "total": total, "advance_to": s["advance"],
        "env_step_outside_advance_to": s["env_step"]}


def run(args) -> dict:
    import torch

    from corn_drake.bench.phases import PhaseTimer
    from corn_drake.bench.bare_physics import bare_physics_rate, check_replayable
    from corn_drake.bench.training.timed_training import (check_counts, run_trainer, train_config,
                                                 trainer_logged_steps_per_s)
    from corn_drake.nn.threads import torch_threads, usable_cpus
    from corn_drake.config.plumbing.diagram_files import load_teacher_config

    env_cfg = load_teacher_config(args.task)
    env_cfg.check()
    check_replayable(env_cfg)
    per_update = args.envs_per_worker * args.rollout_steps
    steps = per_update * args.updates  # timed
    cfg = train_config(args, env_cfg, workers=0, envs_per_worker=args.envs_per_worker)
    timer = PhaseTimer()
    with torch_threads(args.torch_threads):
        trainer, metrics = run_trainer(cfg, timer, args.warmup_updates,
                                       instrument=lambda t: instrument_envs(t, timer))
        bare_rate = bare_physics_rate(trainer.envs.envs[0], args.bare_steps, args.seed)
        threads_used = torch.get_num_threads()
    check_counts(timer, {timer.WINDOW: args.updates, "advance": steps})
    scene_object = trainer.envs.envs[0].scene.object_spec.name
    train_rate = steps / timer.window_seconds
    fractions, seconds = breakdown(timer, bare_rate)
    history = metrics["history"][args.warmup_updates:]  # the timed updates
    return {
        "train_steps_per_s": train_rate,
        "bare_physics_policy_steps_per_s": bare_rate,
        "train_ratio": train_rate / bare_rate,
        "time_fractions": fractions,
        "time_s": seconds,
        # The trainer's own figure (its per-update timer), as a cross-check of the window's.
        "trainer_logged_steps_per_s": trainer_logged_steps_per_s(history, per_update),
        "policy": args.policy,
        "task": env_cfg.task.name,
        "object": scene_object,
        "envs": args.envs_per_worker,
        "updates": args.updates,
        "warmup_updates": args.warmup_updates,
        "rollout_steps": args.rollout_steps,
        "steps": steps,
        "bare_steps": args.bare_steps,
        "episodes_finished": sum(r["episodes"] for r in history),
        "sim_errors": sum(r["sim_errors"] for r in history),
        "physics_steps_per_policy_step": trainer.envs.envs[0].clock.substeps,
        "torque_backend": env_cfg.controller.torque_backend,
        "usable_cpus": usable_cpus(),
        "torch_threads": threads_used,
        "torch_interop_threads": torch.get_num_interop_threads(),
    }
