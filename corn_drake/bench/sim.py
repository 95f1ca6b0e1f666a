"""`corn-drake bench sim`: policy steps/s of TeacherEnv vs bare physics of the same plant.

Baseline ("bare physics"): the same scene (plant + scene graph, same object, same time step) with
no Python systems; its actuation input is fixed once per policy step to the torques the env's
controller produced at that step, so the arm moves and touches things as in the env run.
The overhead ratio is bare steps/s over env steps/s. A cProfile of the env run says where the
time goes.

With --policy KIND, the policy network (and its encoder) is in the loop: a batch of envs in this
process with batched inference, against the same number of envs on Ray rollout workers
(`ray_policy_steps_per_s`, `ray_ratio` = Ray / in-process).
"""

from __future__ import annotations

import cProfile
import io
import pstats
import time

import numpy as np

NAME = "sim"
HELP = "TeacherEnv policy steps/s with random actions vs bare physics of the same plant"


def add_arguments(parser):
    parser.add_argument("--steps", type=int, default=600, help="policy steps per measurement")
    parser.add_argument("--config", default=None, help="teacher diagram YAML (default: diagrams/teacher_rollout.yaml)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--policy", default=None, choices=("corn", "e2e", "state", "pn"),
                        help="also measure with this policy (randomly initialised) in the loop")
    parser.add_argument("--envs", type=int, default=8, help="envs in the policy-in-the-loop runs")
    parser.add_argument("--workers", type=int, default=2, help="Ray workers in the Ray run")


def _run_env(env, steps, rng):
    torques = []
    env.reset(seed=int(rng.integers(1 << 31)))
    ctrl_port = env.handles.controller.GetOutputPort("actuation")
    ctrl_ctx = env.handles.controller.GetMyContextFromRoot(env.context)
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, term, trunc, _ = env.step(rng.uniform(-1, 1, 20))
        torques.append(np.array(ctrl_port.Eval(ctrl_ctx)))
        if term or trunc:
            env.reset()
    return time.perf_counter() - t0, np.array(torques)


def _run_bare(env, torques):
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder

    from corn_drake.scene.builder import build_scene

    builder = DiagramBuilder()
    scene = build_scene(builder, env.cfg.scene, env.scene.object_spec)
    builder.ExportInput(scene.plant.get_actuation_input_port(scene.panda), "tau")
    diagram = builder.Build()
    sim = Simulator(diagram)
    ctx = sim.get_mutable_context()
    # Start from the env's initial state so contacts are comparable.
    scene.plant.SetPositionsAndVelocities(
        scene.plant.GetMyMutableContextFromRoot(ctx),
        env.scene.plant.GetPositionsAndVelocities(env.plant_context))
    port = diagram.GetInputPort("tau")
    period = env.cfg.scene.physics.policy_period
    sim.Initialize()
    t0 = time.perf_counter()
    for tau in torques:
        port.FixValue(ctx, tau)
        sim.AdvanceTo(ctx.get_time() + period)
    return time.perf_counter() - t0


def _policy_loop(batch, agent, steps: int) -> float:
    from corn_drake.rl.agent import obs_to_tensors
    from corn_drake.rl.ppo import sample_actions

    obs = batch.reset()
    for _ in range(3):  # warm-up (Ray actors, first inference)
        obs = batch.step(sample_actions(agent, obs_to_tensors(obs))[0].numpy()).obs
    t0 = time.perf_counter()
    for _ in range(steps):
        obs = batch.step(sample_actions(agent, obs_to_tensors(obs))[0].numpy()).obs
    return steps * len(batch) / (time.perf_counter() - t0)


def _policy_results(args, cfg) -> dict:
    import ray

    from corn_drake.rl.agent import TeacherAgent
    from corn_drake.rl.encoders import make_encoder
    from corn_drake.rl.ray_workers import RayEnvBatch, init_ray
    from corn_drake.rl.vec_env import EnvBatch, EnvFactory

    agent = TeacherAgent(args.policy, make_encoder(args.policy))
    factory = EnvFactory(cfg, args.seed)
    rounds = max(args.steps // args.envs, 10)
    local = _policy_loop(EnvBatch(factory, args.envs), agent, rounds)
    init_ray(num_cpus=args.workers)
    try:
        remote = _policy_loop(RayEnvBatch(factory, args.workers, args.envs // args.workers), agent,
                              rounds)
    finally:
        ray.shutdown()
    return {"policy": args.policy, "envs": args.envs, "ray_workers": args.workers,
            "in_process_policy_steps_per_s": local, "ray_policy_steps_per_s": remote,
            "ray_ratio": remote / local}


def run(args) -> dict:
    from corn_drake.rl.env import TeacherEnv

    env = TeacherEnv(args.config)
    rng = np.random.default_rng(args.seed)
    _run_env(env, 20, rng)  # warm-up
    env_time, torques = _run_env(env, args.steps, rng)
    bare_time = _run_bare(env, torques)
    profiler = cProfile.Profile()
    profiler.enable()
    _run_env(env, min(args.steps, 200), rng)
    profiler.disable()
    stream = io.StringIO()
    pstats.Stats(profiler, stream=stream).sort_stats("tottime").print_stats(12)
    env_rate = args.steps / env_time
    bare_rate = args.steps / bare_time
    physics = env.cfg.scene.physics
    extra = {}
    if args.policy:
        extra = _policy_results(args, env.cfg)
    result = {
        "policy_steps_per_s": env_rate,
        "bare_physics_policy_steps_per_s": bare_rate,
        "overhead_ratio": bare_rate / env_rate,
        "physics_steps_per_policy_step": round(physics.policy_period / physics.time_step),
        "steps": args.steps,
        "object": env.scene.object_spec.name,
        "profile_top_tottime": stream.getvalue().splitlines()[:40],
        **extra,
    }
    if args.policy:
        # With a policy the headline figure is the policy-in-the-loop rate.
        result["env_only_policy_steps_per_s"] = result["policy_steps_per_s"]
        result["policy_steps_per_s"] = extra["in_process_policy_steps_per_s"]
    return result
