"""Choosing primitives by a model of what they do to the object: README.md's items 35, 36, 38.

    # held-out objects: the outcome model's choices against the rank-fitted critic's
    .venv/bin/python docs/results/primitive/outcome_model.py study \
        models/weights/push_turn_primitive --data runs/outcome_data2 \
        --out docs/results/primitive/outcome_model_study.json
    # the model fitted to every state: a run folder that chooses by it (config chooser:
    # outcome_model), evaluated, shipped and shown like any primitive run
    .venv/bin/python docs/results/primitive/outcome_model.py fit \
        models/weights/push_turn_primitive --data runs/outcome_data2 --out-run runs/push_turn_outcome
    corn-drake evaluate --run runs/push_turn_outcome --objects data/library --split unseen \
        --episodes 200 --record 0 --report docs/results/primitive/eval_push_turn_outcome_model.json

The model and the reward it predicts are corn_drake/rl/primitive/outcome/model.py's; the choice among the
actor's motion and a fixed bank of uniform motions at every usable location is
rl/primitive/outcome/chooser.py's.

`study`: each split holds out `--holdout-objects` objects whole; the held-out states' choices
are scored in the rewards the simulator measured (rl/lookahead_distill.scores_quality), against
the run's critic before and after the rank fit of item 34 on the same states and updates.
`fit`: the model fitted to every state of `--data`, written as `--out` (a model file) and/or
`--out-run` (a copy of the run whose actor proposes the motions, with the model as its
outcome_model.pt, `chooser: outcome_model`, and `--task` / `--set` applied to its config as
`corn-drake evaluate` applies them); `--members N` fits N models (seeds S..S+N-1 for `--seed S`,
0 by default; the first the model a plain fit gives) for `outcome.pessimism`, `--tilt` a tilt
classifier (rl/primitive/outcome/tilt_classifier.py) for `outcome.tilt_veto` and `outcome.tilt_blend` (with the
mean reward its data measured for the candidates that tipped or rolled), `--objects N` fits on
the first N objects of one fixed order only (item 40's learning curve over objects). The file
keeps the first member's learning curve (`fit_history`), which `corn-drake ship` writes to the
shipped folder's training_history.json. Data: `lookahead_distill.py collect` folders whose
states hold their outcomes. Everything is written atomically.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from distill_scaling import (BATCH_ROWS, held_out_objects, load_study_data,  # noqa: E402
                             select_states, study_arguments)

from corn_drake.rl.primitive.outcome.lookahead_distill import choice_quality, fit_critic, scores_quality  # noqa: E402
from corn_drake.rl.primitive.outcome.chooser import OutcomeChooser  # noqa: E402
from corn_drake.rl.primitive.outcome.model_file import save_outcome_model  # noqa: E402
from corn_drake.rl.primitive.outcome.model import (INPUT_KINDS, OUTCOME_KEYS,  # noqa: E402
                                         OUTCOME_ROW_KEYS, SCALE, OutcomeModel, data_after,
                                         data_candidates, fit_model, model_inputs,
                                         predicted_rewards)
from corn_drake.rl.primitive.outcome.run_folder import outcome_run_config, write_outcome_run  # noqa: E402
from corn_drake.rl.primitive.agent import load_primitive_run  # noqa: E402
from corn_drake.rl.primitive.outcome.tilt_classifier import (box_contact_features, data_tilted,  # noqa: E402
                                           fit_tilt_classifier)
from corn_drake.storage.atomic_files import write_json  # noqa: E402


def model_quality(model: OutcomeModel, data: dict, tokens: bool, task,
                  progress_reward: float) -> dict:
    """The model's mean keypoint error (m) against "the object does not move"'s, and what its
    choices earned (scores_quality's `chosen`, in the rewards the simulator measured)."""
    candidates = data_candidates(data)
    x, now, frames = model_inputs(candidates, tokens)
    with torch.no_grad():
        prediction = model(x, now)
    truth = data_after(data, frames).numpy()
    error = np.linalg.norm(prediction[0].numpy() - truth, axis=2).mean() / SCALE
    still = np.linalg.norm(now.numpy() - truth, axis=2).mean() / SCALE
    scores = predicted_rewards(candidates, frames, prediction, task, progress_reward)
    return {"keypoint_error_m": float(error), "no_motion_error_m": float(still),
            "chosen": scores_quality(scores, data)["chosen"]}


def study(args) -> None:
    data, objects = load_study_data(args.data, args.holdout_objects,
                                    OUTCOME_KEYS + OUTCOME_ROW_KEYS)
    base, _, _ = load_primitive_run(args.run)
    task, progress = base.env.task, base.primitive.progress_reward
    report = {"run": args.run, "data": [str(d) for d in args.data],
              "states": int(len(data["features_tokens"])), "objects": len(objects),
              "holdout_objects": args.holdout_objects, "updates": args.updates, "splits": []}
    for split in range(args.splits):
        held, _ = held_out_objects(objects, args.holdout_objects, split)
        inside = np.isin(data["object"], held)
        held_out = select_states(data, np.flatnonzero(inside))
        train = select_states(data, np.flatnonzero(~inside))
        row = {"split": split, "train_states": int(len(train["features_tokens"])),
               "held_out_states": int(len(held_out["features_tokens"]))}
        _, critic_agent, _ = load_primitive_run(args.run)
        row["shipped_critic"] = choice_quality(critic_agent, held_out)
        epochs = max(1, round(args.updates / math.ceil(len(train["reward"]) / BATCH_ROWS)))
        fit_critic(critic_agent, train, epochs, batch_size=BATCH_ROWS, loss="rank", seed=split)
        row["rank_critic"] = choice_quality(critic_agent, held_out)
        for tokens in (False, True):
            model = fit_model(train, tokens, args.updates, split)
            row["outcome_model" + ("_tokens" if tokens else "")] = {
                "held_out": model_quality(model, held_out, tokens, task, progress),
                "train": model_quality(model, train, tokens, task, progress)}
        report["splits"].append(row)
        write_json(args.out, report)
        print(f"split {split}: best {row['shipped_critic']['best']:.3f}, shipped critic "
              f"{row['shipped_critic']['chosen']:.3f}, rank critic "
              f"{row['rank_critic']['chosen']:.3f}, outcome model "
              f"{row['outcome_model']['held_out']['chosen']:.3f} (tokens "
              f"{row['outcome_model_tokens']['held_out']['chosen']:.3f}); keypoint error "
              f"{row['outcome_model']['held_out']['keypoint_error_m']:.4f} m against "
              f"{row['outcome_model']['held_out']['no_motion_error_m']:.4f} for no motion",
              flush=True)


def first_objects(data: dict, count: int) -> dict:
    """The states of the first `count` objects of `data` (load_study_data's, folders tagged) in
    one fixed seeded order, so that a smaller count's objects are among a larger's (a learning
    curve over objects), or SystemExit."""
    objects = sorted(set(data["object"]))
    if not 1 <= count <= len(objects):
        raise SystemExit(f"--objects {count}: the data have {len(objects)} objects")
    kept = np.random.default_rng(0).permutation(objects)[:count]
    return select_states(data, np.flatnonzero(np.isin(data["object"], kept)))


def fit(args) -> None:
    if args.out is None and args.out_run is None:
        raise SystemExit("outcome_model.py fit: give --out (a model file) and/or --out-run (a run "
                         "folder that chooses by it)")
    if args.out_run is not None and args.out_run.exists():
        raise SystemExit(f"--out-run {args.out_run}: exists; choose a new folder")
    # Before the fit: the run must load and the overrides apply.
    run_cfg = outcome_run_config(args.run, args.task, args.set) if args.out_run else None
    if args.members < 1:
        raise SystemExit(f"outcome_model.py fit: --members {args.members}: must be >= 1")
    data, _ = load_study_data(args.data, 0, OUTCOME_KEYS + OUTCOME_ROW_KEYS, tag_folders=True)
    if args.objects is not None:
        data = first_objects(data, args.objects)
    facts = {"states": int(len(data["features_tokens"])), "rows": int(len(data["reward"])),
             "data": [str(d) for d in args.data], "updates": args.updates,
             "seed": args.seed, "proposing_run": str(args.run), "input_kind": args.inputs}
    if args.objects is not None:
        facts["objects"] = args.objects
    tilt = None
    if args.tilt:  # checked before any fit: data without a tilt give a classifier nothing
        tilted = data_tilted(data)
        if not tilted.any():
            raise SystemExit(f"--data {' '.join(map(str, args.data))}: no candidate tipped or "
                             "rolled its object; a tilt classifier has nothing to learn")
        tilt = fit_tilt_classifier(box_contact_features(data_candidates(data)), tilted,
                                   args.updates, args.seed)
        facts["tilted_reward"] = float(data["reward"][tilted].mean())  # for outcome.tilt_blend
    # Member k is fitted with seed S + k: member 0 is the model a fit without --members gives.
    history = []  # the first member's learning curve: the shipped folder's training history
    model, *members = [fit_model(data, args.tokens, args.updates, args.seed + k,
                                 history if k == 0 else None, args.inputs)
                       for k in range(args.members)]
    facts["fit_history"] = history
    if run_cfg is not None:  # the run's outcome.* settings must suit the file (one line if not)
        OutcomeChooser([model, *members], args.tokens, facts, tilt).use(run_cfg.outcome)
    if args.out is not None:
        save_outcome_model(args.out, model, args.tokens, members, tilt, **facts)
        print(f"wrote {args.out}")
    if args.out_run is not None:
        write_outcome_run(args.run, run_cfg, model, args.tokens, facts, args.out_run, members,
                          tilt)
        print(f"wrote {args.out_run}: `corn-drake evaluate --run {args.out_run} ...` chooses by "
              f"the model")
    print(f"fitted to {facts['states']} states, {facts['rows']} candidates")


def main() -> None:
    command = sys.argv[1] if len(sys.argv) > 1 else ""
    torch.set_num_threads(1)
    if command == "study":
        parser = study_arguments(__doc__.splitlines()[0])
        study(parser.parse_args(sys.argv[2:]))
    elif command == "fit":
        import argparse

        parser = argparse.ArgumentParser(description="the outcome model fitted to every state")
        parser.add_argument("run", type=Path, help="the primitive run whose actor proposes motions")
        parser.add_argument("--data", type=Path, nargs="+", required=True)
        parser.add_argument("--updates", type=int, default=2000)
        parser.add_argument("--tokens", action="store_true")
        parser.add_argument("--inputs", choices=INPUT_KINDS, default="raw",
                            help="what the model reads: the candidate's own numbers (raw) or "
                                 "object-relative ones (box_contact; item 40)")
        parser.add_argument("--members", type=int, default=1,
                            help="models fitted (seeds S..S+N-1): an ensemble for "
                                 "outcome.pessimism")
        parser.add_argument("--seed", type=int, default=0,
                            help="S, the first member's seed (how far one fit lands from "
                                 "another on the same data)")
        parser.add_argument("--objects", type=int, default=None,
                            help="fit on the states of this many objects only (the first of "
                                 "one fixed order: a learning curve over objects)")
        parser.add_argument("--tilt", action="store_true",
                            help="fit a tilt classifier too (for outcome.tilt_veto and "
                                 "outcome.tilt_blend)")
        parser.add_argument("--out", type=Path, help="the model file")
        parser.add_argument("--out-run", type=Path, help="a run folder that chooses by the model")
        parser.add_argument("--task", default=None, help="the run folder's task (as evaluate --task)")
        parser.add_argument("--set", action="append", default=[], dest="set",
                            help="env.* / primitive.* / outcome.* settings of the run folder "
                                 "(as evaluate's)")
        from corn_drake.errors import InputError

        try:
            fit(parser.parse_args(sys.argv[2:]))
        except InputError as error:  # a bad --run, --task or --set: one line, nothing written
            raise SystemExit(f"outcome_model.py fit: {error}") from None
    else:
        raise SystemExit("usage: outcome_model.py study|fit ... (see the docstring)")


if __name__ == "__main__":
    main()
