"""Random-action episode plans, and stepping an env through them: the workload the simulation
benches (`bench sim`, `bench student`) time, the same plans for every env they compare.

numpy is imported where it is used: `corn-drake bench` imports every module of this folder to
build its parser, which must stay free of numpy, torch and Drake (tests/test_cli_startup.py).
"""

from __future__ import annotations

import time


def random_action_plans(env, steps: int, seed: int):
    """Episode plans [(seed, actions)] adding up to `steps` policy steps."""
    import numpy as np

    from corn_drake.contract import ACTION_DIM

    rng = np.random.default_rng(seed)
    plans, left = [], steps
    while left > 0:
        n = min(left, env.teacher_cfg.task.episode_steps)
        plans.append((int(rng.integers(1 << 31)), rng.uniform(-1, 1, (n, ACTION_DIM))))
        left -= n
    return plans


def run_plans(env, plans):
    """(seconds, final plant states): `env` stepped through every plan, termination ignored."""
    t0 = time.perf_counter()
    finals = []
    for seed, actions in plans:
        env.reset(seed=seed)
        for action in actions:
            env.step(action)  # termination is ignored: the plan fixes the step count
        finals.append(env.scene.plant.GetPositionsAndVelocities(env.plant_context).copy())
    return time.perf_counter() - t0, finals
