"""`corn-drake demo`: the pipeline end to end in about ten minutes on one CPU core, ending with
a policy measurably better than the one it started from.

It times two short probes first (demo_budget.py) and prints what the stages will take on this
machine as busy as it is now; where contact data and pretraining would take it past ten
minutes, it takes the shipped CORN encoder instead (`--encoder auto`, the default) and says so.
On the project machine all six stages take 12.4 minutes on a quiet core, so there it takes the
shipped encoder (9.2 minutes quiet, 9.9 beside a CPU-bound job); `--encoder pretrain` runs
every stage (docs/results/demo/).

1. object library: procedural objects, train and unseen families;
2. contact data (Algorithm 1) from it; 3. contact pretraining of the CORN encoder;
4. the contact-primitive policy (TD3 over the frozen encoder's patch tokens, the project's best
   push policy) evaluated untrained on the unseen objects;
5. its TD3 training on the push task over the train objects;
6. the trained policy on the same unseen episodes (the first recorded to Meshcat HTML), then the
   shipped push_primitive (a full training run) on them too, for scale.

The contact-primitive policy is the stage that learns in the demo's minutes (the dense PPO
teacher needs hours: experiments/primitive_policy/LOG.md). Every stage prints a progress bar with
the time it has left, writes under --out and is skipped or resumed when its output is there, so
a killed demo resumes. demo_summary.json holds the numbers the last lines print.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from corn_drake.arguments.renamed import add_renamed
from corn_drake.arguments.value_types import positive_int, seed_int
from corn_drake.errors import InputError

# The task the demo's policy learns (diagrams/tasks/push.yaml): the object within 5 cm of a
# goal 8-12 cm beyond it.
TASK = "push"
# The shipped policy of that task (models/weights/NAME), evaluated on the same episodes.
SHIPPED_POLICY = "push_primitive"
# The evaluation seed, `corn-drake evaluate`'s default.
EVAL_SEED = 1000
# Primitives per row of the printed learning curve and of metrics.json's history.
LOG_EVERY = 200

NAME = "demo"
HELP = ("learn a push policy end to end in about 10 minutes on one core: library, contact "
        "data and pretraining (or the shipped encoder where they would not fit), TD3 training; "
        "prints its success before and after")


def add_arguments(parser):
    parser.add_argument("--out", default="runs/demo", help="output folder")
    parser.add_argument("--seed", type=seed_int, default=0,
                        help="seed of every stage (library, contact data, pretraining, policy)")
    parser.add_argument("--num-objects", type=positive_int, default=14,
                        help="procedural objects in the demo's library (as `objects "
                             "--num-objects`; 14 gives 12 train and 2 unseen)")
    parser.add_argument("--num-samples", type=positive_int, default=20_000,
                        help="contact-data training samples (as `contact-data --num-samples`)")
    parser.add_argument("--pretrain-steps", type=positive_int, default=600,
                        help="contact-pretraining steps of the CORN encoder")
    parser.add_argument("--train-steps", type=positive_int, default=2400,
                        help="primitives of the policy's TD3 training")
    parser.add_argument("--encoder", choices=("auto", "pretrain", "shipped"), default="auto",
                        help="the policy's frozen encoder: pretrained here (stages 2-3), the "
                             "shipped one (models/weights/push_corn/encoder.pt, 6,000 steps), "
                             "or auto: pretrained here unless that would take the demo past "
                             "ten minutes on this machine as busy as it is now")
    parser.add_argument("--eval-episodes", type=positive_int, default=20,
                        help="episodes of each evaluation on the unseen objects (the same "
                             "objects and goals for the untrained, trained and shipped policy)")
    add_renamed(parser, "--objects", "--num-objects",
                " (a count; --objects is an object library folder in every other command)")
    add_renamed(parser, "--contact-samples", "--num-samples", " (as in `contact-data`)")


def split_counts(num_objects: int, seed: int) -> tuple[int, int]:
    """(train, unseen) objects of the procedural library of `num_objects` at `seed`, as planned
    (assets/splits.py: a pure function of the ids, so known before anything is built)."""
    from corn_drake.assets.library import planned_procedural
    from corn_drake.assets.splits import assign_splits

    planned = planned_procedural(num_objects)
    assign_splits(planned, seed)
    unseen = sum(o.split == "unseen" for o in planned)
    return len(planned) - unseen, unseen


def _check_split(num_objects: int, seed: int) -> None:
    """The demo trains on the library's train objects and evaluates on its unseen ones: a library
    without both is refused before its first stage (issue 63: `--num-objects 1` built a library,
    contact data and an encoder, then failed)."""
    train, unseen = split_counts(num_objects, seed)
    if train and unseen:
        return
    enough = next(n for n in range(num_objects + 1, 200) if all(split_counts(n, seed)))
    raise InputError(f"--num-objects {num_objects}: its library would hold {train} train and "
                     f"{unseen} unseen objects; the demo trains on the one and evaluates on the "
                     f"other: give --num-objects {enough} or more")


def _stage(name: str, t0: float):
    print(f"[demo] {name} ({time.perf_counter() - t0:.0f} s so far)", flush=True)


def run(args) -> int:
    from corn_drake.run_folders.guards import lock_folder, resume_arguments

    _check_split(args.num_objects, args.seed)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: is a file; give a folder")
    with lock_folder(out):
        # Whose folder (issue 63): a new or empty one, or this demo's own with the arguments
        # that define what is there (a rerun resumes; --train-steps may grow).
        resume_arguments(out, {"--seed": args.seed, "--num-objects": args.num_objects,
                               "--num-samples": args.num_samples,
                               "--pretrain-steps": args.pretrain_steps,
                               "--train-steps": args.train_steps},
                         made_by=NAME, may_grow=("--train-steps",),
                         holds_own=lambda f: (f / "library" / "manifest.json").is_file())
        # torch's thread count as every command's `--torch-threads auto` sets it (nn/threads.py):
        # one thread on a 2-CPU machine. torch's own 2 threads wait on each other beside any
        # other busy process: the probe below ran 0.35 s against 0.13 s with one thread beside
        # one CPU-bound job (0.10 against 0.14 quiet), and a newcomer's pretraining took 29 min.
        from corn_drake.nn.threads import auto_torch_threads, torch_threads

        with torch_threads(auto_torch_threads()):
            return _run(args, out)


def _run(args, out: Path) -> int:
    from corn_drake.assets.library import build_procedural
    from corn_drake.assets.processing.process import ProcessConfig
    from corn_drake.config.pretraining import PretrainConfig
    from corn_drake.contact.runner import generate_dataset
    from corn_drake.pretraining.contact import Pretrainer
    from corn_drake.rl.runs.kinds import load_any_run
    from corn_drake.storage.atomic_files import write_json

    t0 = time.perf_counter()
    shipped_encoder = _budget(args, out)

    _stage("1/6 object library", t0)
    process = ProcessConfig()
    process.drops.drops = 32  # stable poses from fewer drops than a full library's 128
    library = out / "library"
    build_procedural(library, args.num_objects, args.seed, process)

    if shipped_encoder:
        _stage("2/6 and 3/6 contact data and pretraining: skipped, the shipped CORN encoder "
               f"({SHIPPED_ENCODER}) instead", t0)
        encoder_file = shipped_encoder_file()
        auroc = _shipped_auroc()
    else:
        _stage("2/6 contact data", t0)
        data = out / "contact_data"
        generate_dataset(library, data, args.num_samples, args.seed)

        _stage("3/6 contact pretraining of the CORN encoder", t0)
        pre = out / "pretrain" / "corn"
        pcfg = PretrainConfig(model="corn", steps=args.pretrain_steps, batch_size=256,
                              warmup_steps=max(args.pretrain_steps // 10, 1),
                              eval_every=max(args.pretrain_steps // 2, 1),
                              checkpoint_every=max(args.pretrain_steps // 2, 1),
                              eval_samples=1024)
        encoder = Pretrainer(pcfg, data, pre).train()  # its metrics.json
        encoder_file = pre / "encoder.pt"
        auroc = encoder.get("unseen_patch_auroc", float("nan"))
    print(f"[demo] encoder: unseen contact AUROC {auroc:.2f} (0.5 = chance; the shipped "
          "encoder's is 0.99 after 6,000 steps)", flush=True)

    run_dir = out / "policy"
    cfg = policy_config(library.resolve(), args)
    objects = unseen_objects(library)

    _stage("4/6 the untrained policy on the unseen objects", t0)
    before = evaluate_on(untrained_agent(cfg, encoder_file), cfg.env, objects,
                         args.eval_episodes, out / "eval_untrained.json", record=0)

    _stage(f"5/6 TD3 training of the policy, {args.train_steps} primitives", t0)
    metrics = train_policy(run_dir, cfg, encoder_file)

    _stage("6/6 the trained policy, then the shipped one, on the same episodes", t0)
    trained = load_any_run(str(run_dir)).agent
    after = evaluate_on(trained, cfg.env, objects, args.eval_episodes, out / "eval_trained.json",
                        record=1)
    shipped_run = load_any_run(str(shipped_folder()))
    shipped_cfg, _ = shipped_run.configure(None, [])  # its own task: push
    shipped = evaluate_on(shipped_run.agent, shipped_cfg.env, objects, args.eval_episodes,
                          out / "eval_shipped.json", record=0)

    summary = {"task": TASK, "episodes": args.eval_episodes, "eval_seed": EVAL_SEED,
               "unseen_objects": [i for i, _ in objects],
               "train_primitives": metrics["global_step"],
               "success": {"untrained": before, "trained": after, "shipped": shipped},
               "encoder": "shipped" if shipped_encoder else "pretrained here",
               "encoder_unseen_auroc": auroc,
               "curve": [{"primitives": h["step"], "success_rate": h["success_rate"]}
                         for h in metrics["history"]],
               "seconds": time.perf_counter() - t0}
    write_json(out / "demo_summary.json", summary)
    for line in closing_lines(summary, out, run_dir):
        print(line)
    return 0


# The encoder the demo takes when pretraining would not fit (models/weights/NAME/encoder.pt).
SHIPPED_ENCODER = "push_corn"
# Where the demo keeps what it chose, so a rerun resumes with the same encoder.
CHOICE_FILE = "encoder_choice.json"


def shipped_encoder_file() -> Path:
    from corn_drake.package_data import data_dir

    return data_dir("models") / "weights" / SHIPPED_ENCODER / "encoder.pt"


def _shipped_auroc() -> float:
    """The shipped encoder's unseen contact AUROC, as its file records its pretraining."""
    from corn_drake.rl.pretrained_encoders import load_encoder

    record = load_encoder("corn", shipped_encoder_file()).pretraining or {}
    return float(record.get("unseen_patch_auroc", float("nan")))


def _budget(args, out: Path) -> bool:
    """Times the probe, prints what the stages will take here now, and returns whether the
    demo takes the shipped encoder. A rerun keeps the first run's choice (its CHOICE_FILE), so
    a resumed demo never switches encoders half-way; an --encoder that contradicts it is
    refused."""
    import json

    from corn_drake.commands import demo_budget
    from corn_drake.storage.atomic_files import write_json

    sizes = {"library": args.num_objects, "contact_data": args.num_samples,
             "pretraining": args.pretrain_steps, "training": args.train_steps,
             "evaluations": args.eval_episodes}
    shipped, expected, slowdowns = demo_budget.plan(sizes, args.encoder)
    chosen = out / CHOICE_FILE
    if chosen.is_file():
        before = json.loads(chosen.read_text())["encoder"]
        if args.encoder not in ("auto", before):
            raise InputError(f"--encoder {args.encoder}: {out} holds a demo built with the "
                             f"{before} encoder; give --encoder {before} or auto, or a new --out")
        shipped = before == "shipped"
    else:
        write_json(chosen, {"encoder": "shipped" if shipped else "pretrain",
                            "slowdowns": slowdowns, "expected_seconds": expected})
    if shipped:
        expected["contact_data"] = expected["pretraining"] = 0.0
    pace = ", ".join(f"{kind} work {factor:.1f}x" for kind, factor in slowdowns.items())
    print(f"[demo] this machine now runs at these times a quiet project core's ({pace}): about "
          f"{max(sum(expected.values()) / 60, 1):.0f} min, against a "
          f"{demo_budget.BUDGET_S / 60:.0f}-minute budget"
          + (f"; with the shipped CORN encoder ({SHIPPED_ENCODER}) in place of contact data and "
             "pretraining here" + (" (--encoder shipped)" if args.encoder == "shipped" else
                                   ", which would not fit (--encoder pretrain makes them)")
             if shipped else "")
          + ". Each stage's bar says what it has left.", flush=True)
    return shipped


def shipped_folder() -> Path:
    from corn_drake.package_data import data_dir

    return data_dir("models") / "weights" / SHIPPED_POLICY


def policy_config(library: Path, args):
    """The demo policy's PrimitiveTrainConfig: `train --policy primitive --task push` on the
    demo library, with the demo's encoder (a few hundred pretraining steps: below the F1 bar
    by design) copied into the run folder as encoder.pt."""
    from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
    from corn_drake.config.plumbing.overrides import on_library
    from corn_drake.config.primitive import PrimitiveTrainConfig
    from corn_drake.rl.checkpoints import OWN_ENCODER

    cfg = on_library(PrimitiveTrainConfig(env=load_primitive_env_config(TASK)), str(library))
    cfg = dataclasses.replace(cfg, encoder=OWN_ENCODER, allow_weak_encoder=True,
                              total_steps=args.train_steps, envs_per_worker=8,
                              log_every=LOG_EVERY, checkpoint_every=LOG_EVERY * 5, seed=args.seed)
    cfg.check()
    return cfg


def untrained_agent(cfg, encoder_file: Path):
    """The weights the demo's training starts from (a resumed demo's trainer holds trained
    ones), in eval mode."""
    from corn_drake.rl.pretrained_encoders import load_encoder
    from corn_drake.rl.training.primitive_trainer import initial_agent

    return initial_agent(cfg, load_encoder("corn", encoder_file, True)).eval()


def train_policy(run_dir: Path, cfg, encoder_file: Path) -> dict:
    """Trains (or resumes) the demo's run as `corn-drake train --policy primitive` does: the
    folder locked, its config and a copy of the encoder written, so it evaluates and ships on its
    own; a demo rerun with other arguments is refused, naming what differs. metrics.json's."""
    from corn_drake.config.primitive import PrimitiveTrainConfig
    from corn_drake.rl.checkpoints import keep_encoder_copy
    from corn_drake.rl.pretrained_encoders import load_encoder
    from corn_drake.rl.training.primitive_trainer import PrimitiveTrainer
    from corn_drake.run_folders.resumable import ResumableRun

    with ResumableRun.open(run_dir, PrimitiveTrainConfig) as run_folder:
        run_folder.refuse_changes(cfg, may_grow=("total_steps",), may_change=(),
                                  name=lambda field: f"demo setting {field}")
        if run_folder.is_new:
            keep_encoder_copy(run_dir, encoder_file)
        trainer = PrimitiveTrainer(cfg, run_dir, load_encoder("corn", encoder_file, True))
        run_folder.write_config(cfg, f"task {TASK}, policy primitive, {cfg.total_steps} "
                                     "primitives")
        return trainer.train()


def unseen_objects(library: Path) -> list:
    from corn_drake.assets.library import list_objects, load_object_spec

    return [(i, load_object_spec(library, i)) for i in list_objects(library, "unseen")]


def evaluate_on(agent, env_cfg, objects, episodes: int, report_path: Path, record: int) -> float:
    """Success rate of `agent` over `episodes` episodes round-robin over `objects` at EVAL_SEED
    (`corn-drake evaluate --split unseen`'s episodes); the report beside, the first `record`
    episodes as Meshcat HTML in REPORT_recordings/."""
    from corn_drake.evaluation.episodes import evaluate
    from corn_drake.storage.atomic_files import write_json

    out_dir = report_path.parent / f"{report_path.stem}_recordings"
    report = evaluate(agent, env_cfg, objects, episodes, record, EVAL_SEED, out_dir,
                      progress=True)
    report.update({"split": "unseen", "actions": "mean"})
    write_json(report_path, report)
    print(f"[demo] success {report['success_rate']:.2f} over {episodes} episodes; report "
          f"{report_path}", flush=True)
    return report["success_rate"]


def closing_lines(summary: dict, out: Path, run_dir: Path) -> list[str]:
    """What the demo built, what its numbers mean and what to run next."""
    s, n = summary["success"], summary["episodes"]
    curve = summary["curve"]
    points = curve[:: max(len(curve) // 6, 1)] + ([curve[-1]] if curve else [])
    shown = ", ".join(f"{p['primitives']}: {p['success_rate']:.2f}"
                      for p in {p["primitives"]: p for p in points}.values())
    verdict = ("it learned" if s["trained"] > s["untrained"]
               else "no gain over the untrained policy: more --train-steps")
    return [
        f"[demo] done in {summary['seconds'] / 60:.1f} min.",
        f"[demo] unseen success on the same {n} episodes ({len(summary['unseen_objects'])} "
        f"unseen objects; success: within 5 cm of a goal 8-12 cm beyond the object): "
        f"untrained {s['untrained']:.2f}, after "
        f"{summary['train_primitives']} primitives {s['trained']:.2f}, shipped {SHIPPED_POLICY} "
        f"{s['shipped']:.2f} -> {verdict}.",
        f"[demo] training success by primitives (the last 100 episodes, exploring): {shown}",
        "[demo] the shipped policy trained 12,000 primitives with a 6,000-step encoder and "
        "reaches 0.84 on the 200 fixed unseen episodes (docs/results/README.md); the untrained "
        "policy succeeds where a random push happens to leave the object within 5 cm.",
        f"[demo] built: {out}/library (objects), "
        + ("" if summary.get("encoder") == "shipped"
           else "contact_data, pretrain/corn/encoder.pt, ")
        + f"{run_dir} (the policy's run: checkpoints, tb/ for TensorBoard, "
        f"plots/learning_curve.png), eval_*.json, eval_trained_recordings/ (Meshcat HTML: open "
        f"it in a browser), demo_summary.json.",
        f"[demo] next: corn-drake evaluate --run {run_dir} --objects {out}/library --split "
        f"unseen --record 1 --keep-open (watch it live in Meshcat); corn-drake train --policy "
        f"primitive --help (a full run); make notebooks.",
    ]
