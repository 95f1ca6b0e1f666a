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
report's folder (and the recordings') are checked writable before the first episode, and the
report is locked while this evaluate works towards it: a second evaluate writing the same file
meanwhile is refused (storage/file_locks.py). A run's report records the checkpoint file and
env steps of the weights it measured (`checkpoint`, `env_steps`), which `ship` checks against
the weights it packs. A progress bar counts the episodes (--no-progress: none), the
recordings' folder (REPORT_recordings/) is printed at the end, and `--keep-open` keeps the
Meshcat server, whose URL is printed before the episodes, alive until Ctrl-C.

Which policy: `--run` names a run of any kind in rl/runs/kinds.py's registry (a `corn-drake
train` run: the teacher, or with `--policy primitive` the contact-primitive policy; a `corn-drake
distill` run: the student; a reference controller; `planner`, the 6D expert), and each kind
declares which of the flags below it takes; rl/runs/kinds.load_any_run loads any of them. A
student is evaluated through the full perception chain (cameras, geometric segmentation, ICP tracking,
observation noise) whatever it was trained with, unless `--perception ground_truth` asks for
the renderer's segmentation (tracking and noise stay on); its report adds `perception` and the
pose-tracking errors (evaluation.tracking_summary).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from corn_drake.arguments.value_types import nonnegative_int, positive_int, seed_int
from corn_drake.errors import InputError

NAME = "evaluate"
HELP = ("evaluate a policy (a teacher, a contact-primitive policy, a student, a reference or the "
        "6D expert): success rate, per object, with Meshcat recordings")


def add_arguments(parser):
    from corn_drake.arguments.episode_workers import add_episode_workers
    from corn_drake.config.choices import SEGMENTATION_MODES
    from corn_drake.arguments.torch_threads import add_torch_threads_argument

    from corn_drake.rl.runs.kinds import RUN_KINDS

    # The kinds are listed from their registry (rl/runs/kinds.py): a new kind is listed here too.
    kinds = "; ".join((f"{', '.join(f'`{n}`' for n in k.NAMES)}: {k.WHAT}" if k.NAMES
                       else f"the folder of {k.WHAT}") + (f" ({k.DETAIL})" if k.DETAIL else "")
                      for k in RUN_KINDS.values())
    parser.add_argument("--run", required=True, help=f"the policy to evaluate: {kinds}")
    parser.add_argument("--objects", default="",
                        help="object library folder (default: the run's object, or its library "
                             "when it was trained with `train --objects`)")
    parser.add_argument("--split", default="unseen", choices=("train", "unseen", "all"),
                        help="which objects of the library the episodes go round-robin over")
    parser.add_argument("--episodes", type=positive_int, default=10,
                        help="episodes in all, round-robin over the objects")
    add_episode_workers(parser, "playing episodes", only="--run planner only: ")
    parser.add_argument("--episodes-from", type=nonnegative_int, default=0, metavar="K",
                        help="play episodes K..--episodes-1 only (to spread them over "
                             "processes; merge-reports joins the parts). Every evaluation "
                             "appends its episodes to REPORT.rows.jsonl as they end, and a "
                             "rerun with the same settings resumes it")
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
    parser.add_argument("--seed", type=seed_int, default=1000,
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
    parser.add_argument("--overwrite", action="store_true",
                        help="replace whatever --report holds, its rows file too, and "
                             "start the episodes afresh (default: only a new path or a report "
                             "of the same --run is written, and its rows resume)")


def _whole_library(obj) -> str:
    """The library of an object config that names all its train objects (library_objects:
    train), as `train --objects` records it; "" for a single object."""
    return obj.library if obj.cycles_library else ""


def _object_specs(args, cfg, card_run: str | None):
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
    # The missing-library error stays with --run's own card (where the default library path
    # comes from); the warning reads `card_run`'s, whose numbers the episodes should match (the
    # expert's: its policy source's run).
    require_library(args.run, library, given=bool(args.objects))
    ids = list_objects(library, None if args.split == "all" else args.split)
    if not ids:
        from corn_drake.assets.library import empty_split_hint

        raise InputError(f"no {args.split} objects in library {library}"
                         f"{empty_split_hint(library, args.split)}")
    if card_run:
        warn_if_other_library(card_run, library, ids)
    skipped = [i for i in list_objects(library) if i not in set(ids)]
    if skipped:  # a library of one's own meshes is split too: say what is left out
        shown = ", ".join(skipped[:6]) + (f" and {len(skipped) - 6} more" if len(skipped) > 6
                                          else "")
        print(f"{len(ids)} {args.split} objects of {library}'s {len(ids) + len(skipped)}; "
              f"skipped (other splits: --split all takes every one): {shown}")
    return [(i, load_object_spec(library, i)) for i in ids]


def run(args) -> int:
    from corn_drake.rl.runs.kinds import run_kind_of
    from corn_drake.storage.atomic_files import ensure_writable
    from corn_drake.storage.file_locks import locked_output

    report_path = Path(args.report)
    out_dir = report_path.parent / f"{report_path.stem}_recordings"
    # Before any episode: a destination that cannot be written would lose all of them.
    if report_path.is_dir():
        raise InputError(f"--report {report_path}: is a folder; give the report file's path")
    ensure_writable(report_path.parent, "--report")
    if args.record > 0:
        ensure_writable(out_dir, "--record")
    _refuse_flags(args, run_kind_of(args.run))
    # One writer per report: a second evaluate into the same file while this one runs is
    # refused, instead of both ending well with one result overwritten (storage/file_locks.py).
    # Released once the report is written, before --keep-open's wait.
    with locked_output(report_path, "--report"):
        meshcat = _evaluate(args, report_path, out_dir)
    if meshcat is not None:
        _wait_for_ctrl_c(meshcat)
    return 0


# Evaluate's flags that only some kinds of run take (rl/runs/kinds.py: each kind's FLAGS), by
# their dest, with how a user spells them.
KIND_FLAGS = {"perception": "--perception", "attention": "--attention",
              "stochastic": "--stochastic", "workers": "--workers",
              "ray_address": "--ray-address"}


def _refuse_flags(args, kind) -> None:
    """The flags this kind of run (a LoadedRun subclass) has no use for, refused in one line
    before anything loads, naming the kinds that take them."""
    from corn_drake.arguments.episode_workers import check_ray_address
    from corn_drake.rl.runs.kinds import kinds_taking

    for dest, flag in KIND_FLAGS.items():
        value = getattr(args, dest)
        if value in (None, False, 0, "") or dest in kind.FLAGS:
            continue
        shown = flag if value is True else f"{flag} {value}"
        takers = " or ".join(k.WHAT for k in kinds_taking(dest))
        hint = f": {kind.HINTS[dest]}" if dest in kind.HINTS else ""
        raise InputError(f"{shown} applies to {takers}; --run {args.run} is {kind.WHAT}{hint}")
    check_ray_address(args)
    if args.record and not kind.RECORDS:
        raise InputError(f"--record {args.record}: --run {args.run} ({kind.WHAT}) records no "
                         "Meshcat episodes yet (it steps the env outside a diagram recording); "
                         "give --record 0")


def _evaluate(args, report_path: Path, out_dir: Path):
    """Loads the run (rl/runs/kinds.py), runs the episodes and writes the report (the finished
    episodes' if interrupted); the Meshcat that --keep-open holds, else None."""
    from corn_drake.evaluation.episodes import evaluate, success_by_group
    from corn_drake.nn.threads import torch_threads
    from corn_drake.rl.runs.kinds import load_any_run
    from corn_drake.storage.atomic_files import write_json

    # The run's own config: the task, controller and object(s) it was trained on; --task and
    # --set are overrides of it.
    loaded = load_any_run(args.run, args.checkpoint)
    run_cfg, overrides = loaded.configure(args.task, args.set)
    if args.attention and not getattr(loaded.agent, "has_attention", False):
        raise InputError(f"--attention: run {args.run} holds a {loaded.policy!r} policy, which "
                         "has no cross-attention over patches (only corn, e2e, p2v-lite and rot "
                         "have one)")
    cfg = run_cfg.env
    cfg.check()  # an override no episode can be built from, before any episode
    print(f"evaluate {args.run} on task {cfg.task.name}"
          + "".join(f"; {change}" for change in overrides))
    objects = _object_specs(args, cfg, loaded.card_run())
    # Which weights were measured (checkpoint, env_steps): what `ship` checks a report against.
    extra = loaded.report_fields()
    # A student is evaluated through the full chain unless --perception says otherwise.
    cfg, seen = loaded.evaluated_env(cfg, args.perception)
    extra |= seen
    if loaded.PERCEIVES:
        print(f"student perception: {cfg.segmentation.mode} segmentation + ICP tracking "
              f"(trained with {seen['trained_perception']})")
    # After every argument is checked, before any episode: what --report holds is this run's
    # to replace, or refused (storage/output_owners.py).
    from corn_drake.storage.output_owners import check_report_owner

    check_report_owner(report_path, str(args.run), args.overwrite)
    if args.overwrite:  # what the report's rows (and labels) were is replaced with it
        _remove_rows_of(report_path)
    meshcat = _open_meshcat() if args.keep_open else None

    # What the report says of the run it measured; a policy's rows file keeps it in its settings.
    measured = {"run": str(args.run), "policy": loaded.policy, **extra,
                "overrides": [dataclasses.asdict(change) for change in overrides],
                "actions": "sampled" if args.stochastic else "mean"}

    def complete_report(report: dict) -> dict:
        report.update(measured)
        report.update({"split": args.split, "library": _library_record(args, run_cfg.env)})
        if args.objects:
            from corn_drake.assets.library import object_groups

            groups = object_groups(args.objects)
            report["success_by_group"] = success_by_group(report["episodes"], groups)
        return report

    try:
        # --stochastic: the diagram samples the actions from a RandomSource seeded per episode.
        if loaded.RUNNER == "planner":
            from corn_drake.evaluation.planner_episodes import evaluate_planner

            report = evaluate_planner(loaded.agent, cfg, objects,
                                      range(args.episodes_from, args.episodes), args.seed,
                                      report_path, progress=not args.no_progress,
                                      workers=args.workers, ray_address=args.ray_address,
                                      library=Path(args.objects) if args.objects else None)
        else:
            from corn_drake.evaluation.episode_rows import rows_path_of
            from corn_drake.evaluation.episodes import report_facts

            # What makes this evaluation (a rerun with the same resumes its rows, another is
            # refused): the diagram, the episodes' objects and seed, the weights, the overrides.
            settings = {"runner": "diagram", **report_facts(cfg), "seed": args.seed,
                        "objects": [o for o, _ in objects], **measured}
            with torch_threads(args.torch_threads):
                report = evaluate(loaded.agent, cfg, objects,
                                  range(args.episodes_from, args.episodes), args.record,
                                  args.seed, out_dir, stochastic=args.stochastic,
                                  attention=args.attention, meshcat=meshcat,
                                  progress=not args.no_progress,
                                  rows_path=rows_path_of(report_path), settings=settings)
    except BaseException as e:  # noqa: BLE001 - an interrupt after some episodes: keep them
        partial = getattr(e, "partial_report", None)
        if partial is not None:
            write_json(report_path, complete_report(partial))
            print(f"partial report of {len(partial['episodes'])} of {args.episodes} episodes "
                  f"(complete: false): {report_path}", file=sys.stderr)
        raise
    report = complete_report(report)
    write_json(report_path, report)
    successes = sum(bool(r.get("success")) for r in report["episodes"])
    # The task's rule counts a pose passed through mid-push (the paper's); the at-rest count
    # beside it says how many successes ended with the object still on its goal.
    print(f"success {report['success_rate']:.2f} (balanced {report['balanced_success_rate']:.2f}) "
          f"over {len(report['episodes'])} episodes, {report['successes_ending_still']} of "
          f"{successes} successes ending at rest; report {report_path}")
    recorded = sum(r.get("recording") is not None for r in report["episodes"])
    if recorded:  # the HTML files are the evaluation's pictures: say where they are
        print(f"recordings: {recorded} episode(s) as Meshcat HTML in {out_dir}/ (open one in a "
              "browser; its animation controls replay the episode)")
    return meshcat


def _remove_rows_of(report_path: Path) -> None:
    """The rows and labels files of REPORT (episode_rows.py), which --overwrite replaces with
    the report: the evaluation starts afresh."""
    from corn_drake.evaluation.episode_rows import rows_path_of
    from corn_drake.evaluation.planner_episodes import labels_path_of
    from corn_drake.rl.planner.labels import plain_path_of

    rows = rows_path_of(report_path)
    for path in (rows, labels_path_of(rows), plain_path_of(labels_path_of(rows))):
        path.unlink(missing_ok=True)


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
