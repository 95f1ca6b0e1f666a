"""`corn-drake demo`: the main job end to end at a small default size.

Stages that exist so far: build the teacher diagram from diagrams/teacher_rollout.yaml, run a
scripted push episode with fixed gains recorded to Meshcat HTML, and measure env vs bare-physics
speed. Later stages (object library, contact data, pretraining, teacher training, evaluation)
join here as they land.
"""

from __future__ import annotations

import time
from pathlib import Path

NAME = "demo"
HELP = "run the pipeline end to end at a small default size; prints where each output went"


def add_arguments(parser):
    parser.add_argument("--out", default="runs/demo", help="output folder")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--bench-steps", type=int, default=200)


def run(args) -> int:
    from pydrake.geometry import Meshcat

    from corn_drake.bench.report import write_report
    from corn_drake.bench.sim import run as bench_sim
    from corn_drake.diagrams import load_teacher_config
    from corn_drake.rl.env import TeacherEnv
    from corn_drake.rl.rollout import run_episode
    from corn_drake.rl.scripted import ScriptedPush

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    outputs = {}
    t0 = time.perf_counter()

    cfg = load_teacher_config()
    env = TeacherEnv(cfg, meshcat=Meshcat())
    pushes = {}

    def on_reset(_obs):
        start = env.episode_info["initial_object_pose"][:3]
        pushes["policy"] = ScriptedPush.toward_table_centre(cfg.controller, start[:2])

    result = run_episode(env, lambda obs: pushes["policy"](obs["hand_state"]), seed=args.seed,
                         max_steps=60, record_path=out / "scripted_push.html", on_reset=on_reset)
    if result.sim_error:
        raise RuntimeError(f"scripted push failed in simulation: {result.sim_error}")
    outputs["scripted push recording (Meshcat HTML)"] = result.recording
    print(f"[demo] scripted push: {result.steps} steps, return {result.total_reward:.3f}, "
          f"final xy error {result.final_status['position_error']:.3f} m")

    bench_args = type("Args", (), {"steps": args.bench_steps, "config": None, "seed": 0,
                                       "policy": None})()
    report_path = out / "bench_sim.json"
    report = write_report(str(report_path), "sim", bench_sim(bench_args))["results"]
    outputs["simulation speed report"] = report_path
    print(f"[demo] env {report['policy_steps_per_s']:.0f} policy steps/s, bare physics "
          f"{report['bare_physics_policy_steps_per_s']:.0f}, overhead {report['overhead_ratio']:.2f}x")

    print(f"[demo] done in {time.perf_counter() - t0:.1f} s. Outputs:")
    for what, path in outputs.items():
        print(f"  {what}: {path}")
    return 0
