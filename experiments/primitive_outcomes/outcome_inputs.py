"""Which inputs carry an outcome model to objects it never saw? experiments/primitive_policy/LOG.md's item 40.

    .venv/bin/python -m experiments.primitive_outcomes.outcome_inputs \
        models/weights/push_turn_primitive --data runs/big_collect --holdout-objects 30 \
        --out docs/results/primitive/outcome_inputs_big_collect.json
    (the same with --data runs/big_collect runs/sources_all --holdout-objects 40
     --out docs/results/primitive/outcome_inputs.json)

Per split, `--holdout-objects` objects are held out whole and the outcome model
(rl/primitive/outcome/model.fit_network, `--updates` updates, seed = split) is fitted on the others' rows
with each kind of input:
  raw           model_inputs' own numbers: the aim, normal, motion and 8 box keypoints in the
                push's frame, and the physics (what every shipped outcome model reads);
  raw_and_box   those and rl/primitive/outcome/model.box_contact_features together;
  box_contact   box_contact_features alone (object-relative: the aim's height as a fraction of
                the box's, the box's proportions along and across the push, ...).
On the held-out states: the mean keypoint error against "the object does not move"'s, and the
choice among each state's candidates in the rewards the simulator measured
(held_out.scores_quality's `chosen`, per primitive; the lookahead's own `best`).
The data are `corn-drake collect-outcomes` folders, object ids tagged by the folder's position.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from corn_drake.rl.primitive.agent import load_primitive_run
from corn_drake.rl.primitive.outcome.data import load_outcome_data, select_states
from corn_drake.rl.primitive.outcome.model import (SCALE, box_contact_features, data_after,
                                                   data_candidates, model_inputs,
                                                   predicted_rewards)
from corn_drake.storage.atomic_files import write_json
from experiments.primitive_outcomes.held_out import (held_out_objects, held_out_prediction,
                                                     scores_quality)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", help="the run whose config gives the task and progress reward")
    parser.add_argument("--data", type=Path, nargs="+", required=True)
    parser.add_argument("--holdout-objects", type=int, default=30)
    parser.add_argument("--splits", type=int, default=3)
    parser.add_argument("--updates", type=int, default=2000)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    torch.set_num_threads(1)
    base, _, _ = load_primitive_run(args.run)
    data = load_outcome_data(args.data)
    objects = sorted(set(data["object"]))
    if args.holdout_objects >= len(objects):
        raise SystemExit(f"--holdout-objects {args.holdout_objects}: the data have only "
                         f"{len(objects)} objects")
    task, progress = base.env.task, base.primitive.progress_reward
    c = data_candidates(data)
    state = data["state"]
    x, now, frames = model_inputs(c, tokens=False)
    target = data_after(data, frames)
    box = box_contact_features(c)
    inputs = {"raw": x, "raw_and_box": torch.cat([x, box], 1), "box_contact": box}
    report = {"run": str(args.run), "data": [str(d) for d in args.data],
              "states": int(len(data["features_tokens"])), "rows": int(len(state)),
              "objects": len(objects), "holdout_objects": args.holdout_objects,
              "updates": args.updates, "splits": []}
    for split in range(args.splits):
        held, _ = held_out_objects(objects, args.holdout_objects, split)
        test = np.flatnonzero(np.isin(data["object"][state], held))
        train = np.setdiff1d(np.arange(len(state)), test)
        held_out = select_states(data, np.flatnonzero(np.isin(data["object"], held)))
        held_c = data_candidates(held_out)  # its rows are `test`, in the same order
        row = {"split": split, "no_motion_error_m": float(np.linalg.norm(
                   now[test].numpy() - target[test].numpy(), axis=2).mean() / SCALE),
               "best": scores_quality(held_out["reward"], held_out)["best"],
               "keypoint_error_m": {}, "chosen": {}}
        for name, features in inputs.items():
            prediction, row["keypoint_error_m"][name] = held_out_prediction(
                features, now, target, train, test, args.updates, split)
            row["chosen"][name] = scores_quality(
                predicted_rewards(held_c, frames[test], prediction, task, progress),
                held_out)["chosen"]
        report["splits"].append(row)
        print(f"split {split}: {row}", flush=True)
    report["mean"] = {key: {k: float(np.mean([r[key][k] for r in report["splits"]]))
                            for k in inputs} for key in ("keypoint_error_m", "chosen")}
    report["mean"]["no_motion_error_m"] = float(np.mean([r["no_motion_error_m"]
                                                         for r in report["splits"]]))
    report["mean"]["best"] = float(np.mean([r["best"] for r in report["splits"]]))
    write_json(args.out, report)
    print(f"wrote {args.out}: {report['mean']}")


if __name__ == "__main__":
    main()
