"""`corn-drake bench sim`: policy steps/s of TeacherEnv vs bare physics of the same plant.

Baseline ("bare physics"): the same scene (plant + scene graph, same object, same domain
randomization, same time step) with no Python systems, driven by the exact torques the env's
controller applied at every physics step (recorded in an untimed pass, replayed through a C++
TrajectorySource), from the same initial states. Both runs therefore simulate the same
trajectories — same contacts, same solver work — and `replay_max_position_error` says how
closely. The overhead ratio is bare steps/s over env steps/s; a cProfile of the env run says
where the time goes.

With --objects LIB [LIB ...], the bare-physics rate of every object of the libraries instead
(bench/episodes/library_physics.py: what a hull budget costs or saves).

With --policy KIND, the policy network (and its encoder) is in the loop: a batch of envs in this
process with batched inference, against the same number of envs on Ray rollout workers
(`ray_policy_steps_per_s`, `ray_ratio` = Ray / in-process).
"""

from __future__ import annotations

import cProfile
import io
import pstats
import time

from corn_drake import DIAGRAMS_DIR
from corn_drake.arguments.renamed import add_renamed
from corn_drake.arguments.value_types import nonnegative_int, positive_int
from corn_drake.bench.bare_physics import check_replayable, record_torques, replay_bare
from corn_drake.rl.policy_kinds import POLICY_KINDS

PREVIOUS_PHYSICS = DIAGRAMS_DIR / "physics" / "previous_default.yaml"

NAME = "sim"
HELP = "TeacherEnv policy steps/s with random actions vs bare physics of the same plant"


def add_arguments(parser):
    parser.add_argument("--steps", type=positive_int, default=600,
                        help="policy steps per measurement")
    parser.add_argument("--task", default=None,
                        help="task overlay: a name in diagrams/tasks/ or a YAML file, as `train "
                             "--task` (default: the base diagram, the paper's 6D task)")
    parser.add_argument("--seed", type=nonnegative_int, default=0,
                        help="seed of the episodes and their random actions")
    parser.add_argument("--repeats", type=positive_int, default=3,
                        help="alternating env / bare-physics runs; the fastest of each is kept")
    parser.add_argument("--policy", default=None, choices=POLICY_KINDS,
                        help="also measure with this policy (randomly initialised) in the loop "
                             "(default: none, random actions only)")
    parser.add_argument("--workers", type=positive_int, default=2,
                        help="Ray workers in the policy-in-the-loop Ray run")
    parser.add_argument("--envs-per-worker", type=positive_int, default=4,
                        help="envs each Ray worker steps; the in-process run steps all of "
                             "them (workers x envs per worker) in one batch")
    parser.add_argument("--baseline-physics", default=str(PREVIOUS_PHYSICS),
                        help="teacher-diagram overlay with the contact settings to compare the "
                             "configured physics against (physics_speedup): by default the "
                             "settings before the throughput work")
    parser.add_argument("--objects", nargs="+", default=None, metavar="LIBRARY",
                        help="bare-physics steps/s of every object of these libraries instead "
                             "(two or more: the same objects, e.g. built with another "
                             "--max-hulls, alternating; ratios to the first; default: none, the "
                             "env measurement)")
    parser.add_argument("--objects-split", default="unseen", choices=("train", "unseen", "all"),
                        help="with --objects: which of the libraries' objects (default: unseen)")
    add_renamed(parser, "--config", "--task", " (a task name or a teacher-diagram YAML, as "
                "`train --task`)")
    add_renamed(parser, "--envs", "--envs-per-worker", " (as in `train`; the in-process run "
                "steps --workers x --envs-per-worker envs)")


def _profile_env(env, plans) -> list[str]:
    from corn_drake.bench.episode_plans import run_plans

    profiler = cProfile.Profile()
    profiler.enable()
    run_plans(env, plans)
    profiler.disable()
    stream = io.StringIO()
    pstats.Stats(profiler, stream=stream).sort_stats("tottime").print_stats(12)
    return stream.getvalue().splitlines()[:40]


def _policy_loop(batch, agent, steps: int) -> float:
    from corn_drake.rl.ppo.agent import obs_to_tensors
    from corn_drake.rl.ppo.ppo import sample_actions

    obs = batch.reset()
    for _ in range(3):  # warm-up (Ray actors, first inference)
        obs = batch.step(sample_actions(agent, obs_to_tensors(obs))[0].numpy()).obs
    t0 = time.perf_counter()
    for _ in range(steps):
        obs = batch.step(sample_actions(agent, obs_to_tensors(obs))[0].numpy()).obs
    return steps * len(batch) / (time.perf_counter() - t0)


def _policy_results(args, cfg) -> dict:
    import ray

    from corn_drake.rl.ppo.agent import TeacherAgent
    from corn_drake.rl.pretrained_encoders import make_encoder
    from corn_drake.rl.workers.ray_workers import RayEnvBatch, init_ray
    from corn_drake.rl.envs.vec_env import EnvBatch, EnvFactory

    agent = TeacherAgent(args.policy, make_encoder(args.policy))
    factory = EnvFactory(cfg, args.seed)
    envs = args.workers * args.envs_per_worker  # the same envs in both runs
    rounds = max(args.steps // envs, 10)
    local = _policy_loop(EnvBatch(factory, envs), agent, rounds)
    init_ray(num_cpus=args.workers)
    try:
        remote = _policy_loop(RayEnvBatch(factory, args.workers, args.envs_per_worker), agent,
                              rounds)
    finally:
        ray.shutdown()
    return {"policy": args.policy, "envs": envs, "ray_workers": args.workers,
            "in_process_policy_steps_per_s": local, "ray_policy_steps_per_s": remote,
            "ray_ratio": remote / local}


def baseline_physics_config(cfg, overlay):
    """`cfg` with `overlay` (a teacher-diagram YAML, e.g. the previous physics defaults) on top;
    a missing or bad file is an InputError naming it."""
    import copy

    from corn_drake.config.teacher import TeacherDiagramConfig
    from corn_drake.config.plumbing.loader import load_config

    base_cfg = load_config(TeacherDiagramConfig, overlay, defaults=copy.deepcopy(cfg))
    base_cfg.check()
    check_replayable(base_cfg)
    return base_cfg


def physics_comparison(env, base_cfg, steps: int, seed: int, repeats: int = 2) -> dict:
    """Bare-physics policy steps/s of `env`'s physics and of the same scene under `base_cfg`'s,
    each replaying its own recording of the same action plans; the two alternate `repeats`
    times and the best of each is kept (the least disturbed by other load)."""
    from corn_drake.bench.episode_plans import random_action_plans
    from corn_drake.rl.envs.teacher_env import TeacherEnv

    baseline = TeacherEnv(base_cfg, spec=env.scene.object_spec)
    plans = random_action_plans(env, steps, seed)
    recorded = {"configured": (env, record_torques(env, plans)),
                "baseline": (baseline, record_torques(baseline, plans))}
    rates = {name: 0.0 for name in recorded}
    for _ in range(repeats):
        for name, (e, rec) in recorded.items():
            rates[name] = max(rates[name], steps / replay_bare(e, rec)[0])
    return {"physics_speedup": rates["configured"] / rates["baseline"],
            "configured_bare_physics_policy_steps_per_s": rates["configured"],
            "baseline_bare_physics_policy_steps_per_s": rates["baseline"],
            "physics": _physics_summary(env.cfg.scene.physics),
            "baseline_physics_settings": _physics_summary(base_cfg.scene.physics)}


def _physics_summary(physics) -> dict:
    plant = physics.plant
    return {"time_step": plant.time_step, "contact_model": plant.contact_model,
            "discrete_contact_approximation": plant.discrete_contact_approximation,
            "compliant_body": physics.compliant_body,
            "table_hydroelastic_modulus": physics.table_hydroelastic_modulus,
            "table_resolution_hint": physics.table_resolution_hint}


def run(args) -> dict:
    import numpy as np

    from corn_drake.bench.episode_plans import random_action_plans, run_plans
    from corn_drake.rl.envs.teacher_env import TeacherEnv

    if args.objects:
        from corn_drake.bench.episodes.library_physics import measure_libraries
        from corn_drake.config.plumbing.diagram_files import load_teacher_config

        cfg = load_teacher_config(args.task)
        return measure_libraries(cfg, args.objects, None if args.objects_split == "all"
                                 else args.objects_split, args.steps, args.seed, args.repeats)
    env = TeacherEnv(args.task)
    check_replayable(env.cfg)
    base_cfg = baseline_physics_config(env.cfg, args.baseline_physics)  # its errors come first
    run_plans(env, random_action_plans(env, 20, args.seed + 1))  # warm-up
    plans = random_action_plans(env, args.steps, args.seed)
    recorded = record_torques(env, plans)
    # Env and bare runs alternate and each keeps its fastest repeat: on these machines one run
    # swung +-30 % against the next with nothing else running, and a drift between two single
    # runs went straight into the ratio.
    env_time = bare_time = float("inf")
    for _ in range(args.repeats):
        elapsed, env_finals = run_plans(env, plans)
        env_time = min(env_time, elapsed)
        elapsed, bare_finals = replay_bare(env, recorded)
        bare_time = min(bare_time, elapsed)
    nq = env.scene.plant.num_positions()
    replay_error = max(float(np.abs(b[:nq] - e[:nq]).max()) for b, e in zip(bare_finals, env_finals))
    determinism_error = max(float(np.abs(r[3] - e).max()) for r, e in zip(recorded, env_finals))
    env_rate, bare_rate = args.steps / env_time, args.steps / bare_time
    result = {
        "policy_steps_per_s": env_rate,
        "bare_physics_policy_steps_per_s": bare_rate,
        "overhead_ratio": bare_rate / env_rate,
        "physics_steps_per_policy_step": env.clock.substeps,
        "steps": args.steps,
        "repeats": args.repeats,
        "episodes": len(plans),
        "object": env.scene.object_spec.name,
        "torque_backend": env.cfg.controller.torque_backend,
        # Same trajectories in both runs: final positions of env vs bare replay, and env vs the
        # recording pass (determinism).
        "replay_max_position_error": replay_error,
        "determinism_max_state_error": determinism_error,
        "profile_top_tottime": _profile_env(env, random_action_plans(env, min(args.steps, 200), args.seed + 2)),
        "baseline_physics": str(args.baseline_physics),
        **physics_comparison(env, base_cfg, args.steps, args.seed, args.repeats),
    }
    if args.policy:
        extra = _policy_results(args, env.cfg)
        result.update(extra)
        # With a policy the headline figure is the policy-in-the-loop rate.
        result["env_only_policy_steps_per_s"] = env_rate
        result["policy_steps_per_s"] = extra["in_process_policy_steps_per_s"]
    return result
