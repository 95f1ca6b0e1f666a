"""`corn-drake label`: the 6D expert's labels on the states of training objects, for the learned
chooser (`corn-drake fit-chooser`, rl/imitation/).

Every state of every episode is searched by the expert (rl/planner/search.py, the settings of
`evaluate --run planner`, `--set planner.*` / `primitive.*` as there), and what the search found
of each root candidate (its simulated reward; in the beam, its two-step value) is kept. Which
primitive is then executed is DAgger's mixture: the expert's choice with probability --beta,
else --learner's (a primitive run, e.g. the last fitted chooser), so later rounds label the
states the learner itself visits. Written beside OUT: OUT.labels.jsonl.gz (the labels: one
gzipped line per episode, rl/planner/labels.py's format, its header naming the library's content
hash, the learner and beta), OUT.rows.jsonl and OUT.json (how the acting mixture did, per episode), all
resumable: a rerun with the same settings plays only the episodes not yet there. The shipped
labels live in models/labels/TASK/ (one file per round), where `fit-chooser` reads them.

Only a library's train objects are labelled: labels on the unseen objects would train the
chooser on the episodes it is evaluated on.
"""

from __future__ import annotations

from pathlib import Path

from corn_drake.arguments.value_types import nonnegative_int, positive_int, seed_int
from corn_drake.errors import InputError

NAME = "label"
HELP = ("label training objects' states with the 6D expert's search (DAgger: the states a "
        "learner visits), the data `fit-chooser` fits")


def add_arguments(parser):
    from corn_drake.arguments.episode_workers import add_episode_workers

    parser.add_argument("--objects", type=Path, required=True,
                        help="object library folder (`corn-drake objects --split train`)")
    parser.add_argument("--episodes", type=positive_int, default=10,
                        help="episodes in all, round-robin over the train objects")
    parser.add_argument("--episodes-from", type=nonnegative_int, default=0, metavar="K",
                        help="play episodes K..--episodes-1 (to spread them over processes)")
    parser.add_argument("--seed", type=seed_int, default=0,
                        help="base seed of the episodes (a new round: a new seed)")
    parser.add_argument("--task", default="full6d", help="the task (as evaluate --task)")
    parser.add_argument("--set", action="append", default=[], dest="set", metavar="KEY=VALUE",
                        help="env.* / primitive.* / planner.* setting (as evaluate --run "
                             "planner's; default: none, the expert's own settings)")
    parser.add_argument("--learner", default=None,
                        help="a primitive run whose choice is executed where the coin says "
                             "so (default: none, the expert acts everywhere)")
    parser.add_argument("--beta", type=float, default=None,
                        help="probability that the expert's choice is executed at a state "
                             "(default: 1 without --learner, 0 with one)")
    parser.add_argument("--out", type=Path, required=True,
                        help="path of the labels without suffix: OUT.labels.jsonl.gz, "
                             "OUT.rows.jsonl and OUT.json are written (e.g. "
                             "models/labels/full6d/round1)")
    add_episode_workers(parser, "labelling episodes")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _labeller(args, primitive, task):
    from corn_drake.evaluation.planner_play import labeller_of

    beta = args.beta if args.beta is not None else (0.0 if args.learner else 1.0)
    if not 0.0 <= beta <= 1.0:
        raise InputError(f"--beta {args.beta}: a probability, in [0, 1]")
    if args.learner is None:
        if beta != 1.0:
            raise InputError(f"--beta {beta}: without --learner only the expert can act "
                             "(give --learner RUN)")
        return None
    return labeller_of({"learner": str(args.learner), "beta": beta}, primitive, task)


def run(args) -> int:
    from corn_drake.arguments.episode_workers import check_ray_address
    from corn_drake.assets.content_hash import library_content_hash
    from corn_drake.assets.library import list_objects, load_object_spec
    from corn_drake.evaluation.planner_episodes import evaluate_planner
    from corn_drake.rl.planner.labels import LABELS_SUFFIX
    from corn_drake.rl.runs.kinds import load_any_run
    from corn_drake.storage.atomic_files import ensure_writable
    from corn_drake.storage.file_locks import locked_output

    if args.episodes_from >= args.episodes:
        raise InputError(f"--episodes-from {args.episodes_from}: no episodes before --episodes "
                         f"{args.episodes}")
    check_ray_address(args)
    if args.out.suffix in (".json", ".jsonl", ".gz"):
        raise InputError(f"--out {args.out}: give the path without a suffix (OUT.labels.jsonl.gz "
                         "and the others are written beside it)")
    if not (args.objects / "manifest.json").is_file():
        raise InputError(f"--objects {args.objects}: no object library (no manifest.json)")
    ids = list_objects(args.objects, "train")
    if not ids:
        raise InputError(f"--objects {args.objects}: no train objects (labels on unseen objects "
                         "would train on the evaluation's episodes; build the train split with "
                         "`corn-drake objects --split train`)")
    loaded = load_any_run("planner")
    run_cfg, overrides = loaded.configure(args.task, args.set)
    labeller = _labeller(args, run_cfg.primitive, run_cfg.env.task)
    objects = [(i, load_object_spec(args.objects, i)) for i in ids]
    report_path = args.out.with_name(args.out.name + ".json")
    ensure_writable(report_path.parent, "--out")
    from corn_drake.storage.output_owners import check_report_owner

    # OUT.json of another run's evaluation is not this labelling's to replace.
    check_report_owner(report_path, "planner", False, flag="--out")
    print(f"label {len(ids)} train objects of {args.objects} on task {run_cfg.env.task.name}, "
          f"episodes {args.episodes_from}..{args.episodes - 1}"
          + (f", the learner {args.learner} acting with probability {1 - labeller.beta:g}"
             if labeller else ", the expert acting")
          + "".join(f"; {change}" for change in overrides))
    facts = {"library_content_hash": library_content_hash(args.objects, ids)}
    with locked_output(report_path, "--out"):
        report = evaluate_planner(loaded.agent, run_cfg.env, objects,
                                  range(args.episodes_from, args.episodes), args.seed,
                                  report_path, progress=not args.no_progress,
                                  labeller=labeller, facts=facts, workers=args.workers,
                                  ray_address=args.ray_address, library=args.objects)
    decisions = report["decisions"]
    print(f"{len(report['episodes'])} episodes, {decisions} labelled states "
          f"({report['decisions_per_core_hour'] or 0:.0f} per core-hour); the acting mixture's "
          f"success {report['success_rate']:.2f}; labels "
          f"{args.out.with_name(args.out.name + LABELS_SUFFIX)}")
    return 0
