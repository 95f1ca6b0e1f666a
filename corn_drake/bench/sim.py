"""`corn-drake bench sim`: policy steps/s of TeacherEnv vs bare physics of the same plant.

Baseline ("bare physics"): the same scene (plant + scene graph, same object, same time step) with
no Python systems; its actuation input is fixed once per policy step to the torques the env's
controller produced at that step, so the arm moves and touches things as in the env run.
The overhead ratio is bare steps/s over env steps/s. A cProfile of the env run says where the
time goes.
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
    parser.add_argument("--policy", default=None,
                        help="also run a policy in the loop (added by the teacher-policy work)")


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
        env.scene.plant.GetPositionsAndVelocities(env._plant_context))
    port = diagram.GetInputPort("tau")
    period = env.cfg.scene.physics.policy_period
    sim.Initialize()
    t0 = time.perf_counter()
    for tau in torques:
        port.FixValue(ctx, tau)
        sim.AdvanceTo(ctx.get_time() + period)
    return time.perf_counter() - t0


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
    return {
        "policy_steps_per_s": env_rate,
        "bare_physics_policy_steps_per_s": bare_rate,
        "overhead_ratio": bare_rate / env_rate,
        "physics_steps_per_policy_step": round(physics.policy_period / physics.time_step),
        "steps": args.steps,
        "object": env.scene.object_spec.name,
        "profile_top_tottime": stream.getvalue().splitlines()[:40],
    }
