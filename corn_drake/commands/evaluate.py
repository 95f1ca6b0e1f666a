"""`corn-drake evaluate`: success of a trained teacher in the evaluation diagram.

A run is evaluated on exactly the env it was trained on: its config.yaml (task, controller
action step, episode length, object or library). `--task` and `--set` override it; what they
change is printed and recorded in the report (`overrides`), with the task's name and the action
step. The policy runs inside the diagram (PolicySystem). Episodes go round-robin over the objects
(the run's object, or the --split objects of a library: --objects, else the one the run was
trained on with `train --objects`); K of them are recorded to Meshcat HTML next to the report.
`--attention` paints a corn / e2e policy's attention on the object's points in those recordings
and in the live Meshcat (viz/attention_view.py).
The report's folder (and the recordings') are checked writable before the first episode.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from corn_drake.cli_types import nonnegative_int, positive_int
from corn_drake.errors import InputError

NAME = "evaluate"
HELP = "evaluate a trained teacher policy (success rate, per object) with Meshcat recordings"
# Reference controllers `--run` accepts in place of a run folder (corn_drake/rl/scripted.py).
REFERENCES = {"scripted": "ScriptedPushAgent", "still": "HoldStillAgent"}


def add_arguments(parser):
    parser.add_argument("--run", required=True,
                        help="run folder written by `corn-drake train`, or a reference: "
                             "`scripted` (straight-line pusher) or `still` (zero action)")
    parser.add_argument("--objects", default="", help="object library folder (default: the run's object)")
    parser.add_argument("--split", default="unseen", choices=("train", "unseen", "all"))
    parser.add_argument("--episodes", type=positive_int, default=10)
    parser.add_argument("--record", type=nonnegative_int, default=1,
                        help="episodes saved as Meshcat HTML")
    parser.add_argument("--task", default=None,
                        help="task overlay (a name in diagrams/tasks/ or a YAML file) instead of "
                             "the run's task; for --run scripted/still, the task to run "
                             "(default: the paper's 6D task)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", dest="set",
                        help="override an env setting of the run's config, e.g. --set "
                             "task.episode_steps=50 (repeatable; printed and recorded in the "
                             "report)")
    parser.add_argument("--seed", type=nonnegative_int, default=1000)
    parser.add_argument("--stochastic", action="store_true",
                        help="sample actions from the policy (as in training) instead of its mean")
    parser.add_argument("--attention", action="store_true",
                        help="paint the policy's cross-attention over the object's patches "
                             "(viridis, every policy step) in the recordings and in the live "
                             "Meshcat (its URL is printed); corn and e2e policies only")
    parser.add_argument("--report", required=True, help="JSON report path")


def _whole_library(obj) -> str:
    """The library of an object config that names all its train objects (library_objects:
    train), as `train --objects` records it; "" for a single object."""
    return obj.library if obj.cycles_library else ""


def _object_specs(args, cfg):
    # --objects, else the run's library when it was trained on a whole one: its --split objects.
    library = args.objects or _whole_library(cfg.scene.object)
    if not library:
        from corn_drake.diagrams import object_spec_from_config

        return [(cfg.scene.object.object_id or cfg.scene.object.kind,
                 object_spec_from_config(cfg.scene.object, cfg.seed))]
    from corn_drake.assets.library import list_objects, load_object_spec

    ids = list_objects(library, None if args.split == "all" else args.split)
    if not ids:
        raise InputError(f"no {args.split} objects in library {library}")
    return [(i, load_object_spec(library, i)) for i in ids]


def run(args) -> int:
    from corn_drake.config import TrainConfig
    from corn_drake.errors import InputError
    from corn_drake.evaluation import evaluate, success_by_group
    from corn_drake.io_utils import ensure_writable, write_json
    from corn_drake.rl.checkpoints import load_run
    from corn_drake.run_config import (apply_sets, config_changes, load_env_config,
                                       replace_task)

    report_path = Path(args.report)
    out_dir = report_path.parent / f"{report_path.stem}_recordings"
    # Before any episode: a destination that cannot be written would lose all of them.
    if report_path.is_dir():
        raise InputError(f"--report {report_path}: is a folder; give the report file's path")
    ensure_writable(report_path.parent, "--report")
    if args.record > 0:
        ensure_writable(out_dir, "--record")
    if args.run in REFERENCES:
        if args.attention:
            raise InputError(f"--attention shows a learned policy's cross-attention; --run "
                             f"{args.run} is a reference controller, which has none")
        if args.stochastic:
            raise InputError(f"--stochastic samples a learned policy; --run {args.run} is a "
                             "deterministic reference controller")
        from corn_drake.rl import scripted

        # A reference has no run: --task chooses its task, --set changes that task.
        base = TrainConfig(env=load_env_config(args.task))
        run_cfg = apply_sets(base, args.set, only="env")
        agent = getattr(scripted, REFERENCES[args.run])(run_cfg.env.controller)
        policy = args.run
    else:
        # The run's own config: the task, controller and object(s) it was trained on;
        # --task and --set are overrides of it.
        base, agent = load_run(args.run)
        run_cfg = replace_task(base, args.task) if args.task is not None else base
        run_cfg = apply_sets(run_cfg, args.set, only="env")
        policy = base.policy
        if args.attention and not agent.has_attention:
            raise InputError(f"--attention: run {args.run} holds a {policy!r} policy, which has "
                             "no cross-attention over patches (only corn and e2e have one)")
    overrides = config_changes(base, run_cfg)
    cfg = run_cfg.env
    cfg.check()  # an override no episode can be built from, before any episode
    print(f"evaluate {args.run} on task {cfg.task.name}"
          + "".join(f"; {change}" for change in overrides))
    # --stochastic: the diagram samples the actions from a RandomSource seeded per episode.
    report = evaluate(agent, cfg, _object_specs(args, cfg), args.episodes, args.record, args.seed,
                      out_dir, stochastic=args.stochastic, attention=args.attention)
    report.update({"run": str(args.run), "policy": policy,
                   "overrides": [dataclasses.asdict(change) for change in overrides],
                   "split": args.split, "actions": "sampled" if args.stochastic else "mean"})
    if args.objects:
        from corn_drake.assets.library import object_groups

        groups = object_groups(args.objects)
        report["success_by_group"] = success_by_group(report["episodes"], groups)
    write_json(report_path, report)
    print(f"success {report['success_rate']:.2f} (balanced {report['balanced_success_rate']:.2f}) "
          f"over {args.episodes} episodes; report {report_path}")
    return 0
