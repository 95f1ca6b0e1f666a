"""`corn-drake demo`: the whole pipeline end to end at a small default size (minutes on a CPU).

1. object library: one procedural object per family (train + unseen families);
2. contact data (Algorithm 1) from it; 3. contact pretraining of the CORN encoder;
4. PPO teacher (`corn` policy, frozen encoder) on the planar task over the train objects;
5. evaluation in the evaluation diagram on an unseen object, recorded to Meshcat HTML: the
   teacher just trained (a few thousand steps: the path works, the policy is not trained), then
   the shipped push teacher (models/weights/push_corn, a real training run) on the push task with
   its attention painted on the object;
plus a scripted push recording and the simulation-speed report. Every stage writes under --out
and is skipped when its output is already complete, so a killed demo resumes.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

from corn_drake.arguments.renamed import add_renamed
from corn_drake.arguments.value_types import positive_int, seed_int

# The teacher's task (diagrams/tasks/planar.yaml): planar goals, learnable in the demo's minutes.
TASK = "planar"
# The shipped weights (models/weights/NAME) the demo evaluates after its own short training.
SHIPPED_TEACHER = "push_corn"
# The evaluation seed, `corn-drake evaluate`'s default.
EVAL_SEED = 1000

NAME = "demo"
HELP = "run the pipeline end to end at a small default size; prints where each output went"


def add_arguments(parser):
    parser.add_argument("--out", default="runs/demo", help="output folder")
    parser.add_argument("--seed", type=seed_int, default=0,
                        help="seed of every stage (library, contact data, pretraining, teacher)")
    parser.add_argument("--num-objects", type=positive_int, default=14,
                        help="procedural objects in the demo's library (as `objects "
                             "--num-objects`)")
    parser.add_argument("--num-samples", type=positive_int, default=20_000,
                        help="contact-data training samples (as `contact-data --num-samples`)")
    parser.add_argument("--pretrain-steps", type=positive_int, default=300,
                        help="contact-pretraining steps of the CORN encoder")
    parser.add_argument("--train-steps", type=positive_int, default=4096, help="teacher env steps")
    parser.add_argument("--eval-episodes", type=positive_int, default=2,
                        help="episodes of each evaluation on the unseen objects")
    parser.add_argument("--bench-steps", type=positive_int, default=200,
                        help="policy steps of the simulation-speed measurement")
    add_renamed(parser, "--objects", "--num-objects",
                " (a count; --objects is an object library folder in every other command)")
    add_renamed(parser, "--contact-samples", "--num-samples", " (as in `contact-data`)")


def _stage(name: str, outputs: dict, t0: float):
    print(f"[demo] {name} ({time.perf_counter() - t0:.0f} s so far)", flush=True)


def run(args) -> int:
    from pydrake.geometry import Meshcat

    from corn_drake.assets.library import build_procedural
    from corn_drake.assets.process import ProcessConfig
    from corn_drake.bench.report import write_report
    from corn_drake.bench.sim import add_arguments as add_bench_sim_arguments
    from corn_drake.bench.sim import run as bench_sim
    from corn_drake.config.pretraining import PretrainConfig
    from corn_drake.pretraining.contact import Pretrainer
    from corn_drake.contact.runner import generate_dataset
    from corn_drake.config.diagram_files import load_teacher_config
    from corn_drake.evaluation.episodes import run_episode
    from corn_drake.package_data import data_dir
    from corn_drake.rl.envs.teacher_env import TeacherEnv
    from corn_drake.rl.scripted import ScriptedPushAgent

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    outputs, t0 = {}, time.perf_counter()

    _stage("1/6 object library", outputs, t0)
    cfg = ProcessConfig()
    cfg.drops.drops = 32
    library = out / "library"
    build_procedural(library, args.num_objects, args.seed, cfg, progress=False)
    outputs["object library"] = library / "manifest.json"

    _stage("2/6 contact data", outputs, t0)
    data = out / "contact_data"
    generate_dataset(library, data, args.num_samples, args.seed, progress=False)
    outputs["contact dataset"] = data / "manifest.json"

    _stage("3/6 contact pretraining", outputs, t0)
    pre = out / "pretrain" / "corn"
    pcfg = PretrainConfig(model="corn", steps=args.pretrain_steps, batch_size=256,
                          warmup_steps=max(args.pretrain_steps // 10, 1),
                          eval_every=max(args.pretrain_steps // 2, 1),
                          checkpoint_every=max(args.pretrain_steps // 2, 1), eval_samples=1024)
    metrics = Pretrainer(pcfg, data, pre).train(progress=False)
    print(f"[demo] unseen patch accuracy {metrics.get('unseen_patch_accuracy', float('nan')):.3f} "
          f"after {args.pretrain_steps} steps")
    outputs["pretraining metrics"] = pre / "metrics.json"
    outputs["frozen encoder"] = pre / "encoder.pt"

    _stage("4/6 teacher PPO (corn)", outputs, t0)
    run_dir = out / "teacher_corn"
    # The demo's pretraining is a few hundred steps: its encoder is below the F1 bar by design.
    train_teacher(run_dir, library.resolve(), pre / "encoder.pt", args)
    outputs["teacher run (TensorBoard in tb/)"] = run_dir
    outputs["run config (what evaluate reads)"] = run_dir / "config.yaml"
    outputs["learning curve"] = run_dir / "plots" / "learning_curve.png"

    _stage("5/6 evaluation on unseen objects", outputs, t0)
    report = out / "eval_corn.json"
    # On the run's own task and action step, read from its config.yaml.
    evaluate_on_unseen(run_dir, library, args.eval_episodes, report)
    outputs["evaluation report"] = report
    outputs["evaluation recording (Meshcat HTML)"] = out / "eval_corn_recordings"
    # The shipped teacher on the demo library's unseen objects: held-out families, the same
    # shapes as its card's (stable poses from the demo's fewer drops), on its own push task.
    shipped = data_dir("models") / "weights" / SHIPPED_TEACHER
    shipped_report = out / "eval_shipped_corn.json"
    evaluate_on_unseen(shipped, library, args.eval_episodes, shipped_report, attention=True)
    outputs["shipped teacher's evaluation (card: models/weights/push_corn/card.json)"] = shipped_report
    outputs["its recording, attention coloured (Meshcat HTML)"] = out / "eval_shipped_corn_recordings"

    _stage("6/6 scripted push + simulation speed", outputs, t0)
    env = TeacherEnv(load_teacher_config(), meshcat=Meshcat())
    result = run_episode(env, ScriptedPushAgent(env.cfg.controller), seed=3, max_steps=60,
                         record_path=out / "scripted_push.html")
    outputs["scripted push recording (Meshcat HTML)"] = result.recording
    # The bench's own parser fills every default, so a flag added to bench sim reaches the demo.
    bench_parser = argparse.ArgumentParser(add_help=False)
    add_bench_sim_arguments(bench_parser)
    bench_args = bench_parser.parse_args(["--steps", str(args.bench_steps)])
    report_path = out / "bench_sim.json"
    sim = write_report(str(report_path), "sim", bench_sim(bench_args))["results"]
    outputs["simulation speed report"] = report_path
    print(f"[demo] env {sim['policy_steps_per_s']:.0f} policy steps/s, bare physics "
          f"{sim['bare_physics_policy_steps_per_s']:.0f}, overhead {sim['overhead_ratio']:.2f}x")

    print(f"[demo] done in {time.perf_counter() - t0:.0f} s. Outputs:")
    for what, path in outputs.items():
        print(f"  {what}: {path}")
    return 0


def train_teacher(run_dir: Path, library: Path, encoder: Path, args) -> None:
    """The demo's `corn` teacher: PPO on the planar task over the library's train objects, the
    same flow as `corn-drake train` (a killed demo resumes the run; one with other demo
    arguments is refused, naming what differs)."""
    from corn_drake.config.diagram_files import load_teacher_config
    from corn_drake.config.overrides import on_library
    from corn_drake.config.training import TrainConfig
    from corn_drake.rl.pretrained_encoders import load_encoder
    from corn_drake.rl.ppo.trainer import Trainer
    from corn_drake.run_folders.resumable import ResumableRun

    cfg = on_library(TrainConfig(env=load_teacher_config(TASK)), str(library))
    cfg = dataclasses.replace(cfg, policy="corn", encoder=str(encoder), allow_weak_encoder=True,
                              total_steps=args.train_steps, envs_per_worker=8, rollout_steps=32,
                              seed=args.seed)
    cfg.check()
    with ResumableRun.open(run_dir, TrainConfig) as run_folder:
        run_folder.refuse_changes(cfg, may_grow=("total_steps",), may_change=(),
                                  name=lambda field: f"demo setting {field}")
        trainer = Trainer(cfg, run_dir, load_encoder(cfg.policy, cfg.encoder, True))
        run_folder.write_config(cfg, f"task {TASK}, policy corn, {cfg.total_steps} steps")
        trainer.train(progress=False)


def evaluate_on_unseen(run: Path, library: Path, episodes: int, report_path: Path,
                       attention: bool = False) -> None:
    """A teacher run evaluated as `corn-drake evaluate --split unseen --record 1` does: on its
    own task, round-robin over the library's unseen objects, the first episode recorded to
    Meshcat HTML beside the report."""
    from corn_drake.assets.library import list_objects, load_object_spec
    from corn_drake.evaluation.episodes import evaluate
    from corn_drake.rl.checkpoints import load_run_with_step
    from corn_drake.storage.atomic_files import write_json

    cfg, agent, env_steps = load_run_with_step(run)
    objects = [(i, load_object_spec(library, i)) for i in list_objects(library, "unseen")]
    out_dir = report_path.parent / f"{report_path.stem}_recordings"
    report = evaluate(agent, cfg.env, objects, episodes, 1, EVAL_SEED, out_dir,
                      attention=attention)
    report.update({"env_steps": env_steps, "checkpoint": "last.pt", "run": str(run),
                   "policy": cfg.policy, "overrides": [], "split": "unseen", "actions": "mean"})
    write_json(report_path, report)
    print(f"[demo] {run.name}: success {report['success_rate']:.2f} over {episodes} episodes; "
          f"report {report_path}")
