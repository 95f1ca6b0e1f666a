"""`corn-drake bench student`: env steps/s of the student env against the teacher env.

The student env (StudentEnv over the student rollout diagram) renders 3 depth cameras, segments
the object (geometric by default: crop, table, robot links, outliers, DBSCAN), tracks its pose
with ICP and adds observation noise at every policy step; the teacher env (TeacherEnv) runs the
same object, task, physics and randomisation without any of it. Both step the same episodes
(seeds) with the same random actions, so `student_to_teacher_ratio` (student steps/s over
teacher steps/s, same run) is what the perception chain costs. The two alternate `--repeats`
times and the fastest of each is kept (run-to-run swings on these machines, see bench sim).

Beside them: the student's evaluation diagram, a randomly initialised StudentPolicy acting
inside it (StudentPolicySystem: its network and GRU in the loop), on the same episodes
(`student_policy_in_loop_steps_per_s`; its actions are the student's, not the random ones).
"""

from __future__ import annotations

import time

from corn_drake.arguments.value_types import nonnegative_int, positive_int

NAME = "student"
HELP = ("student env steps/s with rendering and the full perception chain, vs the teacher env "
        "on the same object and task (student_to_teacher_ratio)")


def add_arguments(parser):
    from corn_drake.config.choices import SEGMENTATION_MODES

    parser.add_argument("--steps", type=positive_int, default=40,
                        help="policy steps per measurement (40: well under a minute here)")
    parser.add_argument("--config", default=None,
                        help="student diagram YAML, read on top of the defaults like "
                             "diagrams/student_rollout.yaml (the default)")
    parser.add_argument("--perception", choices=SEGMENTATION_MODES, default="geometric",
                        help="segmentation in the student env (geometric: the full chain)")
    parser.add_argument("--repeats", type=positive_int, default=2,
                        help="alternating student / teacher runs; the fastest of each is kept")
    parser.add_argument("--seed", type=nonnegative_int, default=0,
                        help="seed of the episodes and their random actions")


def _run_policy_in_diagram(env, plans) -> float:
    """Seconds to run `plans`' episodes (their seeds and lengths) with the diagram's policy."""
    t0 = time.perf_counter()
    for seed, actions in plans:
        env.reset(seed=seed)
        for _ in actions:
            env.step()
    return time.perf_counter() - t0


def measure(cfg, steps: int, seed: int = 0, repeats: int = 2) -> dict:
    import torch

    from corn_drake.bench.episode_plans import random_action_plans, run_plans
    from corn_drake.nn.student import StudentPolicy
    from corn_drake.rl.envs.teacher_env import TeacherEnv
    from corn_drake.rl.envs.student_env import StudentEnv

    student_env = StudentEnv(cfg)
    spec = student_env.scene.object_spec
    teacher_env = TeacherEnv(cfg.teacher, spec=spec)
    torch.manual_seed(seed)
    policy_env = StudentEnv(cfg, spec=spec, student=StudentPolicy().eval())
    plans = random_action_plans(student_env, steps, seed)
    warm_up = random_action_plans(student_env, 2, seed + 1)  # renderer, first ICP, first inference
    run_plans(student_env, warm_up)
    run_plans(teacher_env, warm_up)
    _run_policy_in_diagram(policy_env, warm_up)
    student_time = teacher_time = float("inf")
    for _ in range(repeats):
        student_time = min(student_time, run_plans(student_env, plans)[0])
        teacher_time = min(teacher_time, run_plans(teacher_env, plans)[0])
    policy_time = _run_policy_in_diagram(policy_env, plans)
    student_rate, teacher_rate = steps / student_time, steps / teacher_time
    camera = cfg.cameras.camera
    return {
        "student_env_steps_per_s": student_rate,
        "teacher_env_steps_per_s": teacher_rate,
        "student_to_teacher_ratio": student_rate / teacher_rate,
        "student_policy_in_loop_steps_per_s": steps / policy_time,
        "steps": steps,
        "repeats": repeats,
        "episodes": len(plans),
        "object": spec.name,
        "task": cfg.teacher.task.name,
        "cameras": f"{len(cfg.cameras.eyes)} x {cfg.cameras.mode} {camera.width}x{camera.height}",
        "segmentation": cfg.segmentation.mode,
        "num_points": cfg.segmentation.num_points,
        "observation_noise": {"cloud_noise_std": cfg.observation.cloud_noise_std,
                              "goal_noise_std": cfg.observation.goal_noise_std},
    }


def run(args) -> dict:
    from corn_drake.config.plumbing.diagram_files import load_student_config

    cfg = load_student_config(args.config)
    cfg.segmentation.mode = args.perception
    cfg.check()
    return measure(cfg, args.steps, args.seed, args.repeats)
