"""`corn-drake evaluate`: success of a trained teacher or student in the evaluation diagram.

A run is evaluated on exactly the env it was trained on: its config.yaml (task, controller
action step, episode length, object or library). `--task` and `--set` override it (for a
student run, the teacher part of its student diagram; for a primitive run also its executor's
`primitive.*` settings); what they change is printed and recorded
in the report (`overrides`), with the task's name and the action step. The policy runs inside
the diagram (PolicySystem, or for a student StudentPolicySystem with its GRU state in the
context). Episodes go round-robin over the objects (the run's object, or the --split objects of
a library: --objects, else the one the run was trained on with `train --objects`); K of them
are recorded to Meshcat HTML next to the report; `--attention` paints a corn / e2e policy's
attention on the object's points there and in the live Meshcat (viz/attention_view.py). The
report's folder (and the recordings') are
checked writable before the first episode. A progress bar counts the episodes (--no-progress:
none), the recordings' folder (REPORT_recordings/) is printed at the end, and `--keep-open`
keeps the Meshcat server, whose URL is printed before the episodes, alive until Ctrl-C.

Which policy: `--run` names a `corn-drake train` run (the teacher), a `corn-drake distill` run
(the student: its config.yaml is a DistillConfig), or a reference controller. A student is
evaluated through the full perception chain (cameras, geometric segmentation, ICP tracking,
observation noise) whatever it was trained with, unless `--perception ground_truth` asks for
the renderer's segmentation (tracking and noise stay on); its report adds `perception` and the
pose-tracking errors (evaluation.tracking_summary).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from corn_drake.arguments.value_types import nonnegative_int, positive_int
from corn_drake.errors import InputError

NAME = "evaluate"
HELP = ("evaluate a trained teacher or student policy (success rate, per object) with Meshcat "
        "recordings")
# Reference controllers `--run` accepts in place of a run folder (corn_drake/rl/scripted.py).
REFERENCES = {"scripted": "ScriptedPushAgent", "still": "HoldStillAgent"}


def add_arguments(parser):
    from corn_drake.config.choices import SEGMENTATION_MODES
    from corn_drake.arguments.torch_threads import add_torch_threads_argument

    parser.add_argument("--run", required=True,
                        help="run folder written by `corn-drake train` (teacher) or `corn-drake "
                             "distill` (student), or a reference: `scripted` (straight-line "
                             "pusher) or `still` (zero action)")
    parser.add_argument("--objects", default="",
                        help="object library folder (default: the run's object, or its library "
                             "when it was trained with `train --objects`)")
    parser.add_argument("--split", default="unseen", choices=("train", "unseen", "all"),
                        help="which objects of the library the episodes go round-robin over")
    parser.add_argument("--episodes", type=positive_int, default=10,
                        help="episodes in all, round-robin over the objects")
    parser.add_argument("--record", type=nonnegative_int, default=1, metavar="N",
                        help="the first N episodes saved as Meshcat HTML in REPORT_recordings/ beside the "
                             "report (0: none)")
    parser.add_argument("--task", default=None,
                        help="task overlay (a name in diagrams/tasks/ or a YAML file) instead of "
                             "the run's task; for --run scripted/still, the task to run "
                             "(default: the paper's 6D task)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", dest="set",
                        help="override an env setting of the run's config, e.g. --set "
                             "task.episode_steps=50, or for a primitive run its executor's, "
                             "e.g. primitive.success_at_rest=true (repeatable; printed and "
                             "recorded in the report; default: none, the run's own settings)")
    parser.add_argument("--seed", type=nonnegative_int, default=1000,
                        help="base seed: episode k on an object is seeded from it, the object's id "
                             "and k (the same --seed gives the same episodes)")
    parser.add_argument("--stochastic", action="store_true",
                        help="sample actions from the policy (as in training) instead of its mean")
    parser.add_argument("--perception", choices=SEGMENTATION_MODES, default=None,
                        help="student runs only: the segmentation of the perception chain "
                             "(default geometric, the full chain whatever the student was "
                             "trained with; ground_truth: the renderer's labels, ICP tracking "
                             "and observation noise still on)")
    parser.add_argument("--attention", action="store_true",
                        help="paint the policy's cross-attention over the object's patches "
                             "(viridis, every policy step) in the recordings and in the live "
                             "Meshcat (its URL is printed); corn, e2e, p2v-lite and rot policies only")
    parser.add_argument("--checkpoint", default="",
                        help="teacher runs only: a kept checkpoint's file name in RUN/checkpoints "
                             "(e.g. step_000204800.pt, written with `train --set "
                             "snapshot_every=N`) instead of last.pt (default: last.pt)")
    add_torch_threads_argument(parser, "the policy's inference")
    parser.add_argument("--keep-open", action="store_true",
                        help="keep the Meshcat server alive after the episodes, until Ctrl-C: "
                             "its URL is printed at the start; the live view shows every episode "
                             "and its animation controls replay the recorded ones")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--report", required=True, help="JSON report path")


def _whole_library(obj) -> str:
    """The library of an object config that names all its train objects (library_objects:
    train), as `train --objects` records it; "" for a single object."""
    return obj.library if obj.cycles_library else ""


def _object_specs(args, cfg):
    # --objects, else the run's library when it was trained on a whole one: its --split objects.
    library = args.objects or _whole_library(cfg.scene.object)
    if not library:
        from corn_drake.builders.teacher import object_spec_from_config

        return [(cfg.scene.object.object_id or cfg.scene.object.kind,
                 object_spec_from_config(cfg.scene.object, cfg.seed))]
    from corn_drake.assets.library import list_objects, load_object_spec
    from corn_drake.evaluation.shipped_card import require_library, warn_if_other_library

    # A shipped folder's card: a missing library names the command that builds it; another
    # library than the card's gets a warning (its episodes cannot match the card's report).
    require_library(args.run, library, given=bool(args.objects))
    ids = list_objects(library, None if args.split == "all" else args.split)
    if not ids:
        raise InputError(f"no {args.split} objects in library {library}")
    warn_if_other_library(args.run, library, ids)
    return [(i, load_object_spec(library, i)) for i in ids]


def run(args) -> int:
    from corn_drake.config.training import TrainConfig
    from corn_drake.errors import InputError
    from corn_drake.evaluation.episodes import evaluate, success_by_group
    from corn_drake.storage.atomic_files import ensure_writable, write_json
    from corn_drake.nn.threads import torch_threads
    from corn_drake.rl.checkpoints import load_run_with_step
    from corn_drake.config.overrides import apply_sets, config_changes
    from corn_drake.config.diagram_files import load_teacher_config, replace_task
    from corn_drake.run_folders.config_file import run_kind

    report_path = Path(args.report)
    out_dir = report_path.parent / f"{report_path.stem}_recordings"
    # Before any episode: a destination that cannot be written would lose all of them.
    if report_path.is_dir():
        raise InputError(f"--report {report_path}: is a folder; give the report file's path")
    ensure_writable(report_path.parent, "--report")
    if args.record > 0:
        ensure_writable(out_dir, "--record")
    kind = "reference" if args.run in REFERENCES else run_kind(
        args.run, or_else=f"a reference ({', '.join(REFERENCES)})")
    if args.checkpoint and kind not in ("train", "primitive"):
        raise InputError(f"--checkpoint {args.checkpoint} picks one of a teacher run's kept "
                         f"checkpoints; --run {args.run} is not a `corn-drake train` run")
    if args.perception is not None and kind != "distill":
        what = ("a reference controller" if kind == "reference"
                else "a teacher run (`corn-drake train`)")
        raise InputError(f"--perception {args.perception} applies to a student run (written by "
                         f"`corn-drake distill`); --run {args.run} is {what}")
    student_cfg, extra = None, {}
    if args.run in REFERENCES:
        if args.attention:
            raise InputError(f"--attention shows a learned policy's cross-attention; --run "
                             f"{args.run} is a reference controller, which has none")
        if args.stochastic:
            raise InputError(f"--stochastic samples a learned policy; --run {args.run} is a "
                             "deterministic reference controller")
        from corn_drake.rl import scripted

        # A reference has no run: --task chooses its task, --set changes that task.
        base = TrainConfig(env=load_teacher_config(args.task))
        run_cfg = apply_sets(base, args.set, only="env")
        agent = getattr(scripted, REFERENCES[args.run])(run_cfg.env.controller)
        policy = args.run
    else:
        # The run's own config: the task, controller and object(s) it was trained on;
        # --task and --set are overrides of it.
        if kind == "distill":
            from corn_drake.rl.checkpoints import load_student_run

            distill_cfg, agent = load_student_run(args.run)
            student_cfg = distill_cfg.env
            # The student diagram's teacher part takes --task / --set exactly as a teacher
            # run's env does.
            base, policy = TrainConfig(env=student_cfg.teacher), "student"
        elif kind == "primitive":
            from corn_drake.rl.primitive.agent import load_primitive_run

            base, agent, env_steps = load_primitive_run(args.run, args.checkpoint)
            policy = base.policy
            extra = {"env_steps": env_steps, "env_steps_unit": "primitives",
                     "checkpoint": agent.checkpoint_file, "chooser": base.chooser}
            if agent.outcome_chooser is not None:
                extra["outcome_model"] = agent.outcome_chooser.facts
        else:
            base, agent, env_steps = load_run_with_step(args.run, args.checkpoint)
            policy = base.policy
            # The file the weights came from: prev.pt when last.pt was unusable.
            extra = {"env_steps": env_steps,
                     "checkpoint": getattr(agent, "checkpoint_file", args.checkpoint or "last.pt")}
        if kind == "primitive":
            from corn_drake.config.diagram_files import primitive_run_on

            # A primitive run's executor settings (its config's `primitive:`) are the policy's
            # own, so --set reaches them too, e.g. primitive.success_at_rest=true.
            run_cfg = primitive_run_on(base, args.task, args.set)
            agent.primitive_config = run_cfg.primitive
            # An outcome-model chooser predicts the evaluated task's reward and success, and
            # chooses as the run's `outcome:` settings say, --set included.
            agent.task = run_cfg.env.task
            if agent.outcome_chooser is not None:
                agent.outcome_chooser.use(run_cfg.outcome)
        else:
            run_cfg = replace_task(base, args.task) if args.task is not None else base
            run_cfg = apply_sets(run_cfg, args.set, only="env")
        if kind == "primitive" and (args.attention or args.stochastic):
            # Refused before any env is built, in one line naming the flag.
            flag = "--attention" if args.attention else "--stochastic"
            raise InputError(f"{flag}: run {args.run} holds the contact-primitive policy, which "
                             "chooses greedily and has no cross-attention; its Meshcat view "
                             "(--record, --keep-open) shows its contact point, push and scores")
        if args.attention and not getattr(agent, "has_attention", False):
            raise InputError(f"--attention: run {args.run} holds a {policy!r} policy, which has "
                             "no cross-attention over patches (only corn, e2e, p2v-lite and rot have one)")
    overrides = config_changes(base, run_cfg)
    cfg = run_cfg.env
    cfg.check()  # an override no episode can be built from, before any episode
    print(f"evaluate {args.run} on task {cfg.task.name}"
          + "".join(f"; {change}" for change in overrides))
    objects = _object_specs(args, cfg)
    if student_cfg is not None:
        trained_with = student_cfg.segmentation.mode
        # Evaluated through the full chain unless --perception says otherwise.
        student_cfg = dataclasses.replace(
            student_cfg, teacher=cfg,
            segmentation=dataclasses.replace(student_cfg.segmentation,
                                             mode=args.perception or "geometric"))
        student_cfg.check()
        cfg = student_cfg
        extra |= {"trained_perception": trained_with,
                 "observation_noise": dataclasses.asdict(student_cfg.observation)}
        print(f"student perception: {student_cfg.segmentation.mode} segmentation + ICP tracking "
              f"(trained with {trained_with})")
    meshcat = _open_meshcat() if args.keep_open else None
    # --stochastic: the diagram samples the actions from a RandomSource seeded per episode.
    def complete_report(report: dict) -> dict:
        report.update(extra)
        report.update({"run": str(args.run), "policy": policy,
                       "overrides": [dataclasses.asdict(change) for change in overrides],
                       "split": args.split, "actions": "sampled" if args.stochastic else "mean",
                       "library": _library_record(args, run_cfg.env)})
        if args.objects:
            from corn_drake.assets.library import object_groups

            groups = object_groups(args.objects)
            report["success_by_group"] = success_by_group(report["episodes"], groups)
        return report

    try:
        with torch_threads(args.torch_threads):
            report = evaluate(agent, cfg, objects, args.episodes, args.record, args.seed,
                              out_dir, stochastic=args.stochastic, attention=args.attention,
                              meshcat=meshcat, progress=not args.no_progress)
    except BaseException as e:  # noqa: BLE001 - an interrupt after some episodes: keep them
        partial = getattr(e, "partial_report", None)
        if partial is not None:
            write_json(report_path, complete_report(partial))
            print(f"partial report of {len(partial['episodes'])} of {args.episodes} episodes "
                  f"(complete: false): {report_path}", file=sys.stderr)
        raise
    report = complete_report(report)
    write_json(report_path, report)
    print(f"success {report['success_rate']:.2f} (balanced {report['balanced_success_rate']:.2f}) "
          f"over {args.episodes} episodes; report {report_path}")
    recorded = min(args.record, args.episodes)
    if recorded:  # the HTML files are the evaluation's pictures: say where they are
        print(f"recordings: {recorded} episode(s) as Meshcat HTML in {out_dir}/ (open one in a "
              "browser; its animation controls replay the episode)")
    if meshcat is not None:
        _wait_for_ctrl_c(meshcat)
    return 0


def _library_record(args, env_cfg) -> dict | None:
    """The object library the episodes came from, for the report: its path and the sha256 of
    its manifest (None for a run on a primitive object), so a report says what it measured."""
    import hashlib

    library = args.objects or _whole_library(env_cfg.scene.object)
    if not library:
        return None
    manifest = Path(library) / "manifest.json"
    digest = hashlib.sha256(manifest.read_bytes()).hexdigest()
    return {"path": str(library), "manifest_sha256": digest}


def _open_meshcat():
    """The Meshcat that --keep-open holds after the episodes, its URL printed before them so the
    live view can be opened while they run."""
    from pydrake.geometry import Meshcat

    meshcat = Meshcat()
    print(f"Meshcat live view: {meshcat.web_url()}", flush=True)
    return meshcat


def _wait_for_ctrl_c(meshcat) -> None:
    """Keeps the process, and with it the Meshcat server, alive until Ctrl-C (SIGINT)."""
    import time

    print(f"Meshcat stays open at {meshcat.web_url()}; press Ctrl-C to close it", flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        print("closed Meshcat", flush=True)
