"""`corn-drake pretrain`: contact pretraining of the CORN encoder and/or the PointNet baseline, or
pretext pretraining of the same patch encoder for the P2V-lite and ROT baselines.

With --model both, CORN and PointNet are trained on the same data and batch, in OUT/corn and
OUT/pointnet for the same number of steps (--pointnet-budget steps, the paper's protocol), or in
OUT/pointnet_equal_time for the same optimisation wall-clock (--pointnet-budget time: CORN's
recorded train_seconds divided by PointNet's measured seconds per step; PointNet is ~10x slower
per step on a CPU). The two PointNet runs are separate rows, never one folder: OUT/metrics.json
holds CORN's metrics with each PointNet run's under its folder name, and OUT/encoder.pt is the
frozen CORN encoder for `corn-drake train --policy corn`.
OUT is locked while the command runs; resuming refuses changed arguments (see RESUME_MAY_GROW).

With --model p2v-lite or rot the data is an object library's clouds (--objects, not --data; see
corn_drake/pretext/) and the run is OUT/p2v-lite or OUT/rot: config.yaml, checkpoints/,
tb/, metrics.json (held-out and unseen pretext loss and skill) and encoder.pt, the frozen
encoder for `corn-drake train --policy p2v-lite|rot`. Only that folder is locked and written,
so one OUT can hold the contact runs and both pretext runs side by side.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from corn_drake.arguments.value_types import positive_float, positive_int, seed_int

NAME = "pretrain"
HELP = ("pretrain the patch encoder on gripper contact, or on a pretext task (p2v-lite, rot) "
        "(resumes from OUT/MODEL/checkpoints/last.pt)")
CONTACT_MODELS = ("corn", "pointnet", "both")
PRETEXT_MODELS = ("p2v-lite", "rot")


def add_arguments(parser):
    parser.add_argument("--data", default=None,
                        help="contact-data folder (--model corn, pointnet, both; default: none)")
    parser.add_argument("--objects", default=None,
                        help="object library folder whose clouds are the pretext data "
                             "(--model p2v-lite, rot; default: none)")
    parser.add_argument("--out", required=True, help="run folder, e.g. runs/pretrain")
    parser.add_argument("--model", choices=CONTACT_MODELS + PRETEXT_MODELS, default="both",
                        help="corn (the contact-pretrained patch encoder), pointnet (its "
                             "baseline), both, or a pretext baseline (p2v-lite, rot)")
    parser.add_argument("--steps", type=positive_int, default=2000, help="optimiser steps")
    parser.add_argument("--pointnet-steps", type=positive_int, default=None,
                        help="PointNet steps (overrides --pointnet-budget; default: from --pointnet-budget)")
    parser.add_argument("--pointnet-budget", choices=("steps", "time"), default="steps",
                        help="with --model both: PointNet gets CORN's steps or CORN's wall-clock")
    parser.add_argument("--lr", type=positive_float, default=None,
                        help="peak learning rate (default: the model's config)")
    parser.add_argument("--batch-size", type=positive_int, default=None,
                        help="default: 1024 for contact pretraining (the paper's), 512 for "
                             "p2v-lite and rot (point2vec's)")
    parser.add_argument("--eval-every", type=positive_int, default=250,
                        help="steps between held-out evaluations (and checkpoints)")
    parser.add_argument("--eval-samples", type=positive_int, default=None,
                        help="held-out samples per evaluation (default: 4096 contact, 1024 "
                             "pretext)")
    parser.add_argument("--seed", type=seed_int, default=0,
                        help="seed of the initialisation and the batches")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args) -> int:
    from corn_drake.contact.shards import list_shards
    from corn_drake.errors import InputError
    from corn_drake.run_folders.guards import lock_folder, resume_arguments

    if args.model in PRETEXT_MODELS:
        return _pretrain_pretext(args, Path(args.out))
    if args.objects is not None:
        raise InputError(f"--objects is the data of --model p2v-lite or rot; --model {args.model} "
                         "pretrains on contact data (--data)")
    if args.data is None:
        raise InputError(f"--model {args.model} needs --data (a contact-data folder written by "
                         "`corn-drake contact-data`)")
    if args.batch_size is None:
        args.batch_size = 1024
    for model in ["corn", "pointnet"] if args.model == "both" else [args.model]:
        # Every setting checked (its bounds and relations: --lr below min_lr, say) before
        # OUT/arguments.json is written.
        _contact_config(args, model, args.pointnet_steps if model == "pointnet" and
                        args.pointnet_steps else args.steps).check()
    list_shards(args.data, "train")  # a missing or empty dataset fails before OUT is touched
    out = Path(args.out)
    with lock_folder(out):
        # Without a record (a folder from before records named their command), a pretraining
        # output is known by its merged metrics or a model's checkpoints folder.
        resume_arguments(out, {"--data": os.path.normpath(args.data)}, made_by=NAME,
                         holds_own=lambda f: (f / "metrics.json").is_file() or any(
                             (f / m / "checkpoints").is_dir() for m in ("corn", "pointnet")))
        return _pretrain(args, out)


def _pretrain(args, out: Path) -> int:
    from corn_drake.config.pretraining import PretrainConfig
    from corn_drake.pretraining.contact import Pretrainer
    from corn_drake.storage.atomic_files import read_json, write_json, write_text
    from corn_drake.run_folders.guards import refuse_changed_config
    from pydrake.common.yaml import yaml_dump_typed

    models = ["corn", "pointnet"] if args.model == "both" else [args.model]
    results = {}
    for model in models:
        steps, budget = args.steps, {"kind": "steps"}
        if model == "pointnet" and args.pointnet_steps:
            steps = args.pointnet_steps
            budget = {"kind": "steps_given"}
        elif model == "pointnet" and args.pointnet_budget == "time" and "corn" in results:
            from corn_drake.pretraining.contact import seconds_per_step

            previous = out / "pointnet_equal_time" / "config.yaml"
            per_step = seconds_per_step("pointnet", args.batch_size)
            steps = max(1, round(results["corn"]["train_seconds"] / per_step))
            if previous.exists():  # resuming: keep the step count the run started with
                from corn_drake.config.plumbing.loader import load_config

                steps = load_config(PretrainConfig, previous).steps
            budget = {"kind": "equal_wall_clock", "corn_train_seconds": results["corn"]["train_seconds"],
                      "pointnet_seconds_per_step": per_step}
            print(f"pointnet: {steps} steps = CORN's {results['corn']['train_seconds']:.0f} s "
                  f"at {per_step:.2f} s/step")
        cfg = _contact_config(args, model, steps)
        cfg.check()
        # The equal-time PointNet is its own labelled row: it must never resume, or be mistaken
        # for, the equal-steps one.
        label = "pointnet_equal_time" if budget["kind"] == "equal_wall_clock" else model
        run_dir = out / label
        # Refusals (other arguments, an unreadable checkpoint) come before the first write.
        refuse_changed_config(run_dir, run_dir / "config.yaml", cfg, may_grow=RESUME_MAY_GROW,
                              ignore=RESUME_MAY_CHANGE, name=argument_of_field)
        pretrainer = Pretrainer(cfg, args.data, run_dir)
        run_dir.mkdir(parents=True, exist_ok=True)
        write_text(run_dir / "config.yaml", yaml_dump_typed(cfg))
        results[label] = {**pretrainer.train(progress=not args.no_progress), "budget": budget}
        print(f"{label}: unseen patch accuracy "
              f"{results[label].get('unseen_patch_accuracy', float('nan')):.3f}, "
              f"F1 {results[label].get('unseen_patch_f1', float('nan')):.3f}")
    merged_path = out / "metrics.json"
    merged = read_json(merged_path, "pretraining metrics") if merged_path.exists() else {}
    if "corn" in results:
        merged.update({k: v for k, v in results.pop("corn").items() if k != "budget"})
        shutil.copyfile(out / "corn" / "encoder.pt", out / "encoder.pt")
    merged.update(results)  # "pointnet" and/or "pointnet_equal_time", each with its budget
    write_json(merged_path, merged)
    print(f"wrote {merged_path}")
    return 0


def _contact_config(args, model: str, steps: int):
    """The PretrainConfig of contact model `model` trained for `steps` with the arguments."""
    from corn_drake.config.pretraining import PretrainConfig

    extra = {} if args.lr is None else {"lr": args.lr}
    if args.eval_samples is not None:
        extra["eval_samples"] = args.eval_samples
    return PretrainConfig(model=model, steps=steps, batch_size=args.batch_size, **extra,
                          warmup_steps=min(100, max(steps // 10, 1)), eval_every=args.eval_every,
                          checkpoint_every=args.eval_every, seed=args.seed)


def _pretrain_pretext(args, out: Path) -> int:
    from corn_drake.config.pretraining import PretextConfig, pretext_config
    from corn_drake.assets.library_clouds import load_object_clouds
    from corn_drake.errors import InputError
    from corn_drake.storage.atomic_files import write_text
    from corn_drake.pretraining.pretext import PretextPretrainer
    from corn_drake.run_folders.guards import lock_folder, refuse_changed_config, resume_arguments
    from pydrake.common.yaml import yaml_dump_typed

    if args.data is not None:
        raise InputError(f"--data is contact data; --model {args.model} pretrains on an object "
                         "library's clouds (--objects)")
    if args.objects is None:
        raise InputError(f"--model {args.model} needs --objects (an object library folder "
                         "written by `corn-drake objects`)")
    if args.pointnet_steps is not None or args.pointnet_budget != "steps":
        raise InputError("--pointnet-steps and --pointnet-budget are for --model both")
    fields = {"batch_size": args.batch_size or PretextConfig.batch_size,
              "eval_every": args.eval_every, "checkpoint_every": args.eval_every, "seed": args.seed}
    if args.lr is not None:
        fields["lr"] = args.lr
    if args.eval_samples is not None:
        fields["eval_samples"] = args.eval_samples
    cfg = pretext_config(args.model, steps=args.steps, **fields)
    load_object_clouds(args.objects)  # an unusable library fails before OUT is touched
    run_dir = out / args.model
    with lock_folder(run_dir):
        # Refusals (another library, other arguments, an unreadable checkpoint or library) come
        # before the first write.
        resume_arguments(run_dir, {"--objects": os.path.normpath(args.objects)}, made_by=NAME,
                         holds_own=lambda f: (f / "config.yaml").is_file())
        refuse_changed_config(run_dir, run_dir / "config.yaml", cfg, may_grow=RESUME_MAY_GROW,
                              ignore=RESUME_MAY_CHANGE, name=argument_of_field)
        pretrainer = PretextPretrainer(cfg, args.objects, run_dir)
        write_text(run_dir / "config.yaml", yaml_dump_typed(cfg))
        metrics = pretrainer.train(progress=not args.no_progress)
    print(f"{args.model}: unseen pretext skill {metrics.get('unseen_pretext_skill', float('nan')):.3f} "
          f"(loss {metrics.get('unseen_pretext_loss', float('nan')):.4f}, input-blind reference "
          f"{metrics.get('unseen_pretext_reference_loss', float('nan')):.4f}); "
          f"encoder {run_dir / 'encoder.pt'}")
    return 0


# A resumed model (OUT/MODEL holds config.yaml) must be given the arguments it started with,
# except: --steps / --pointnet-steps may grow (warmup_steps follows from them); --eval-every
# (eval_every, checkpoint_every), --eval-samples and --no-progress may change. --data is
# recorded in OUT/arguments.json (--objects in OUT/MODEL/arguments.json for a pretext model).
RESUME_MAY_GROW = ("steps",)
RESUME_MAY_CHANGE = ("warmup_steps", "eval_every", "checkpoint_every", "eval_samples")
_FIELD_ARGUMENTS = {"model": "--model", "steps": "--steps (or --pointnet-steps)",
                    "batch_size": "--batch-size", "lr": "--lr", "seed": "--seed"}


def argument_of_field(field: str) -> str:
    """The pretrain argument behind a PretrainConfig / PretextConfig field, for refusal
    messages."""
    return _FIELD_ARGUMENTS.get(field, f"config field {field}")
