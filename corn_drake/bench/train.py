"""`corn-drake bench train`: training steps/s of the real PPO trainer vs bare physics, same run.

The trainer (corn_drake/rl/trainer.py, in-process envs, the push task by default, a randomly
initialised encoder) runs a few updates; then the bare plant of the same scene is driven by
recorded torques exactly as `bench sim` does it (bench/sim.py bare_physics_rate), on one of the
trainer's own envs. `train_ratio` = train / bare is the fraction of the physics-only speed that
training keeps (issue 14 asks >= 0.8).

Rates and shares are measured on the timed updates only: after --warmup-updates untimed ones
(the first rollout and update pay torch's and the simulators' first calls: 2 s against 0.2 s in
a probe here), each from entering the rollout to leaving the PPO update (the first reset,
tensorboard and checkpoints are one-time or per-update bookkeeping outside, as in the trainer's
own steps_per_s, reported beside it), with timers put on the instances of this run
(bench/phases.py), so the trainer runs its production code:
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

from corn_drake.cli_types import nonnegative_int, positive_int

NAME = "train"
HELP = "PPO training steps/s vs bare physics of the same scene, with where the time goes"

FRACTION_KEYS = ("physics", "python_systems", "policy_inference", "ppo_update",
                 "object_switching", "other")


def add_arguments(parser):
    parser.add_argument("--policy", default="corn", choices=("corn", "e2e", "state", "pn"),
                        help="policy trained (a randomly initialised encoder: timing only)")
    parser.add_argument("--task", default="push",
                        help="task overlay: a name in diagrams/tasks/ or a YAML file")
    parser.add_argument("--envs", type=positive_int, default=32, help="envs, in this process")
    parser.add_argument("--updates", type=positive_int, default=3, help="PPO updates timed")
    parser.add_argument("--warmup-updates", type=nonnegative_int, default=1,
                        help="PPO updates run first, untimed (first calls into torch and the "
                             "simulators cost far more than later ones)")
    parser.add_argument("--rollout-steps", type=positive_int, default=32,
                        help="policy steps per env and update")
    parser.add_argument("--bare-steps", type=positive_int, default=300,
                        help="policy steps of the bare-physics replay")
    parser.add_argument("--seed", type=nonnegative_int, default=0)
    parser.add_argument("--torch-threads", type=positive_int, default=None,
                        help="torch.set_num_threads for this run (default: torch's own choice, "
                             "as `train` runs); the report records the count used")


def instrument(trainer, timer, warmup_updates: int = 0) -> None:
    """Timers on this trainer's rollout, env batch, envs and PPO update (instances only); the
    first `warmup_updates` updates run untimed."""
    from corn_drake.bench.phases import time_simulator

    batch = trainer.envs
    original_collect, original_update = trainer._collect, trainer.ppo.update
    original_begin = batch._begin_episode

    started = [0]  # updates begun

    def collect(*args, **kwargs):
        started[0] += 1
        if started[0] > warmup_updates:
            timer.open_window()  # closed when this update's PPO step returns
        with timer.phase("collect"):
            return original_collect(*args, **kwargs)

    def update(*args, **kwargs):
        with timer.phase("ppo_update"):
            result = original_update(*args, **kwargs)
        if timer.in_window:
            timer.close_window()
        return result

    def begin_episode(slot):
        with timer.phase("object_switching"):
            obs = original_begin(slot)
        time_simulator(batch.envs[slot], timer, "advance")  # an env swapped in is timed too
        return obs

    trainer._collect, trainer.ppo.update, batch._begin_episode = collect, update, begin_episode
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
        "policy_inference": s["collect"],
        "ppo_update": s["ppo_update"],
        "object_switching": s["object_switching"],
        "other": s[timer.WINDOW],
    }
    total = timer.window_seconds
    return {k: v / total for k, v in seconds.items()}, {
        **seconds, "total": total, "advance_to": s["advance"],
        "env_step_outside_advance_to": s["env_step"]}


def run(args) -> dict:
    import os
    import tempfile

    import torch

    from corn_drake.bench.phases import PhaseTimer
    from corn_drake.bench.sim import bare_physics_rate, check_replayable
    from corn_drake.config import TrainConfig
    from corn_drake.rl.encoders import make_encoder
    from corn_drake.rl.trainer import Trainer
    from corn_drake.run_config import load_env_config

    env_cfg = load_env_config(args.task)
    env_cfg.check()
    check_replayable(env_cfg)
    per_update = args.envs * args.rollout_steps
    steps = per_update * args.updates  # timed
    total = per_update * (args.warmup_updates + args.updates)
    cfg = TrainConfig(policy=args.policy, total_steps=total, workers=0, envs_per_worker=args.envs,
                      rollout_steps=args.rollout_steps, seed=args.seed, env=env_cfg)
    threads_before = torch.get_num_threads()
    if args.torch_threads is not None:
        # Measured here on a 2-core machine with another process busy: batch-32 inference
        # took 0.7 s with torch's 2 threads, 0.017 s with 1 (threads waiting on each other).
        torch.set_num_threads(args.torch_threads)
    timer = PhaseTimer()
    try:
        with tempfile.TemporaryDirectory(prefix="bench_train_") as out:
            trainer = Trainer(cfg, out, make_encoder(args.policy))
            instrument(trainer, timer, args.warmup_updates)
            metrics = trainer.train(progress=False)
            bare_rate = bare_physics_rate(trainer.envs.envs[0], args.bare_steps, args.seed)
            scene_object = trainer.envs.envs[0].scene.object_spec.name
        threads_used = torch.get_num_threads()
    finally:
        # The setting is process-wide: a caller in the same process (a notebook, the tests)
        # gets its own back.
        torch.set_num_threads(threads_before)
    if timer.calls[timer.WINDOW] != args.updates or timer.calls["advance"] != steps:
        raise RuntimeError(f"timed {timer.calls[timer.WINDOW]} updates and "
                           f"{timer.calls['advance']} policy steps, expected {args.updates} and "
                           f"{steps}: the trainer no longer runs through the timed methods")
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
        "trainer_logged_steps_per_s": steps / sum(per_update / r["steps_per_s"] for r in history),
        "policy": args.policy,
        "task": env_cfg.task.name,
        "object": scene_object,
        "envs": args.envs,
        "updates": args.updates,
        "warmup_updates": args.warmup_updates,
        "rollout_steps": args.rollout_steps,
        "steps": steps,
        "bare_steps": args.bare_steps,
        "episodes_finished": sum(r["episodes"] for r in history),
        "sim_errors": sum(r["sim_errors"] for r in history),
        "physics_steps_per_policy_step": trainer.envs.envs[0].clock.substeps,
        "torque_backend": env_cfg.controller.torque_backend,
        "usable_cpus": len(os.sched_getaffinity(0)),
        "torch_threads": threads_used,
        "torch_interop_threads": torch.get_num_interop_threads(),
    }

