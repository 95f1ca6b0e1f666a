"""Bare physics of a scene: the torques an env's controller applied, recorded in an untimed pass
and replayed on the same plant and scene graph with no Python systems (a C++ TrajectorySource),
from the same initial states. `bench sim` (the env's overhead), `bench sim --objects` (each
library object's cost) and `bench train` (train_ratio) all time physics this way.
"""

from __future__ import annotations

import time

from corn_drake.errors import InputError


def record_torques(env, plans):
    """Untimed pass: per episode the DR sample, initial state and per-physics-step torques."""
    import numpy as np

    clock, h = env.clock, env.clock.time_step
    ctrl = env.handles.controller
    recorded = []
    for seed, actions in plans:
        env.reset(seed=seed)
        x0 = env.scene.plant.GetPositionsAndVelocities(env.plant_context).copy()
        ctrl_ctx = ctrl.GetMyContextFromRoot(env.context)
        torques = []
        for k, action in enumerate(actions):
            env._action_port.FixValue(env.context, action)
            for j in range(1, clock.substeps + 1):
                # AdvanceTo(m h) stops right before the plant update at m h (events at the end
                # time run at the start of the next call): the controller's output now is the
                # torque that update uses.
                env.simulator.AdvanceTo((k * clock.substeps + j) * h)
                torques.append(np.array(ctrl.GetOutputPort("actuation").Eval(ctrl_ctx)))
            env.simulator.AdvanceTo(clock.boundary(k + 1))
        recorded.append((env.episode.physics, x0, np.array(torques),
                         env.scene.plant.GetPositionsAndVelocities(env.plant_context).copy()))
    return recorded


def replay_bare(env, recorded):
    import numpy as np

    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import TrajectorySource
    from pydrake.trajectories import PiecewisePolynomial

    from corn_drake.scene.builder import build_scene
    from corn_drake.scene.randomization import apply_physics

    clock = env.clock
    builder = DiagramBuilder()
    scene = build_scene(builder, env.cfg.scene, env.scene.object_spec)
    dummy = PiecewisePolynomial.ZeroOrderHold([0.0, 1.0], np.zeros((7, 2)))
    source = builder.AddSystem(TrajectorySource(dummy))
    builder.Connect(source.get_output_port(), scene.plant.get_actuation_input_port(scene.panda))
    diagram = builder.Build()
    sim = Simulator(diagram)
    ctx = sim.get_mutable_context()
    default = diagram.CreateDefaultContext()
    plant_ctx = scene.plant.GetMyMutableContextFromRoot(ctx)
    elapsed, finals = 0.0, []
    for sample, x0, torques, _ in recorded:
        # Torque m is used by the plant update at time (m + 1) h.
        times = clock.time_step * np.arange(1, len(torques) + 2)
        source.UpdateTrajectory(PiecewisePolynomial.ZeroOrderHold(
            times, np.vstack([torques, torques[-1:]]).T))
        ctx.SetTimeStateAndParametersFrom(default)
        ctx.SetTime(clock.boundary(0))
        apply_physics(scene, sample, ctx, 1.0)
        scene.plant.SetPositionsAndVelocities(plant_ctx, x0)
        sim.Initialize()
        n_policy = len(torques) // clock.substeps
        t0 = time.perf_counter()
        for k in range(n_policy):  # same AdvanceTo pattern as the env: one call per policy step
            sim.AdvanceTo(clock.boundary(k + 1))
        elapsed += time.perf_counter() - t0
        finals.append(scene.plant.GetPositionsAndVelocities(plant_ctx).copy())
    return elapsed, finals


def check_replayable(cfg) -> None:
    """The bare replay rebuilds the scene with the env's object as built: refuses a config whose
    episodes rescale the object (their torques would be replayed on the wrong size)."""
    if cfg.randomization.object_radius is not None:
        raise InputError("the bare-physics replay needs a fixed-size object: set "
                         "randomization.object_radius to null (no size randomization)")


def bare_physics_rate(env, steps: int, seed: int) -> float:
    """Policy steps/s of the bare plant of `env`'s scene, replaying the torques of `steps`
    random-action policy steps recorded on `env` (untimed) from the same initial states."""
    from corn_drake.bench.episode_plans import random_action_plans

    elapsed, _ = replay_bare(env, record_torques(env, random_action_plans(env, steps, seed)))
    return steps / elapsed
