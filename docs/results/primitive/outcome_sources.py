"""Where the primitives' outcomes vary: README.md's item 37.

    .venv/bin/python docs/results/primitive/outcome_sources.py runs/sources_plain \
        runs/sources_settle10 --splits 3 --out docs/results/primitive/outcome_sources.json

Each argument is a `lookahead_distill.py collect` folder (its states hold every candidate's
outcome). Per folder:
  moving_at_choice  the states at which every candidate moved the object more than 5 mm (mean
                    box-keypoint distance): the object was still rolling or sliding when the
                    primitive was chosen, whatever was chosen;
  tilted            the candidates after which the object's up direction (the world's vertical
                    in its own frame) turned by more than 20 degrees: it tipped or rolled;
  tilted_share_of_squared_motion
                    their part of the summed squared keypoint motion, what a model's squared
                    error is measured against;
  not_moved         the candidates that left the object within 5 mm of where it was.
Motions are the reward's: the box keypoints with the origin's height dropped
(rl/outcome_model.data_after).

With --splits S, per folder and per split (--holdout-objects objects held out whole, the
first --object-fractions of the others fitted): the outcome model (rl/outcome_model.fit_model,
--updates updates) and rl/primitive/outcome/tilt_classifier.py's classifier of `tilted`, on the model's own
inputs and on that module's box-and-contact features (its docstring), each measured on the
fitted objects and on the held-out ones: keypoint error against "no motion", and the
classifiers' ROC AUC. What a model of the primitives learns of the objects it saw against what
carries over to others, and how that grows with the number of objects it saw.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from distill_scaling import held_out_objects, select_states  # noqa: E402
from lookahead_distill import load_data  # noqa: E402 - the collect folders' reader

from corn_drake.rl.primitive.outcome.model import (OUTCOME_KEYS,  # noqa: E402
                                         OUTCOME_ROW_KEYS, SCALE, data_after, data_candidates,
                                         fit_model, model_inputs)
from corn_drake.rl.primitive.outcome.tilt_classifier import (TILT_DEG, box_contact_features,  # noqa: E402
                                           data_tilted, fit_tilt_classifier)
from corn_drake.storage.atomic_files import write_json  # noqa: E402

MOVED_M = 0.005


def sources(data: dict) -> dict:
    """The figures of one folder's data (see the module docstring)."""
    _, now, frames = model_inputs(data_candidates(data), tokens=False)
    motion = np.linalg.norm(data_after(data, frames).numpy() - now.numpy(), axis=2).mean(1) / SCALE
    tilted = data_tilted(data)
    state = data["state"]
    least = np.full(int(state.max()) + 1, np.inf)
    np.minimum.at(least, state, motion)
    return {"states": int(len(least)), "candidates": int(len(motion)),
            "objects": int(len(set(data["object"]))) if "object" in data else None,
            "moving_at_choice": float(np.mean(least > MOVED_M)),
            "tilted": float(tilted.mean()),
            "tilted_share_of_squared_motion": float((motion[tilted] ** 2).sum() /
                                                    (motion ** 2).sum()),
            "not_moved": float(np.mean(motion <= MOVED_M)),
            "mean_keypoint_motion_m": float(motion.mean()),
            "still_after": float(np.mean(data["still_after"]))}


def roc_auc(label: np.ndarray, score: np.ndarray) -> float:
    """The probability that a random positive scores above a random negative (ties: half)."""
    label = np.asarray(label, bool)
    positive, negative = score[label], score[~label]
    if not len(positive) or not len(negative):
        return float("nan")
    above = (positive[:, None] > negative[None]).mean() + \
        0.5 * (positive[:, None] == negative[None]).mean()
    return float(above)


def _measured(model, classifiers, data: dict) -> dict:
    """`classifiers`: (on the model's inputs, on the box-and-contact features)."""
    x, now, frames = model_inputs(data_candidates(data), tokens=False)
    truth = data_after(data, frames).numpy()
    with torch.no_grad():
        after = model(x, now)[0].numpy()
        logits = classifiers[0](x).numpy()
        box_logits = classifiers[1](box_contact_features(data_candidates(data))).numpy()
    tilted = data_tilted(data)
    return {"keypoint_error_m": float(np.linalg.norm(after - truth, axis=2).mean() / SCALE),
            "no_motion_error_m": float(np.linalg.norm(now.numpy() - truth, axis=2).mean()
                                       / SCALE),
            "tilt_auc": roc_auc(tilted, logits),
            "tilt_auc_box_contact_features": roc_auc(tilted, box_logits)}


def cross_object_fits(data: dict, holdout: int, splits: int, updates: int,
                      fractions: list[float]) -> list[dict]:
    """Per split and fraction: the model and the classifier fitted on that fraction of the
    objects not held out (`holdout` of them, the same for every fraction of a split), measured
    on the fitted ones and the held-out ones."""
    objects = sorted(set(data["object"]))
    if holdout >= len(objects):
        raise SystemExit(f"--holdout-objects {holdout}: the data have only {len(objects)} "
                         "objects")
    out = []
    for split in range(splits):
        held, rest = held_out_objects(objects, holdout, split)
        held_out = select_states(data, np.flatnonzero(np.isin(data["object"], held)))
        for fraction in fractions:
            used = rest[:max(1, round(fraction * len(rest)))]
            train = select_states(data, np.flatnonzero(np.isin(data["object"], used)))
            model = fit_model(train, tokens=False, updates=updates, seed=split)
            x, _, _ = model_inputs(data_candidates(train), tokens=False)
            tilted = data_tilted(train)
            classifiers = (fit_tilt_classifier(x, tilted, updates, split),
                           fit_tilt_classifier(box_contact_features(data_candidates(train)),
                                               tilted, updates, split))
            out.append({"split": split, "train_objects": len(used),
                        "fitted": _measured(model, classifiers, train),
                        "held_out": _measured(model, classifiers, held_out)})
            print(f"  split {split}: {out[-1]}", flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", type=Path, nargs="+")
    parser.add_argument("--splits", type=int, default=0,
                        help="object splits for the cross-object fits (0: none)")
    parser.add_argument("--holdout-objects", type=int, default=6)
    parser.add_argument("--updates", type=int, default=4000)
    parser.add_argument("--object-fractions", type=float, nargs="+", default=[1.0],
                        help="fit on these fractions of the objects not held out")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    bad = [f for f in args.object_fractions if not 0.0 < f <= 1.0]
    if bad:
        raise SystemExit(f"--object-fractions must be in (0, 1], got {bad[0]}")
    torch.set_num_threads(1)
    report = {"moved_m": MOVED_M, "tilt_deg": TILT_DEG, "splits": args.splits,
              "holdout_objects": args.holdout_objects, "updates": args.updates,
              "object_fractions": args.object_fractions, "folders": {}}
    for folder in args.folders:
        files = sorted(folder.glob("episodes_*.npz"))
        data = load_data(files) if files else {}
        missing = [k for k in OUTCOME_KEYS + OUTCOME_ROW_KEYS if k not in data]
        if missing:
            raise SystemExit(f"{folder}: no episodes_*.npz files, or files without "
                             f"{', '.join(missing)} (collected before outcomes were stored)")
        report["folders"][str(folder)] = figures = sources(data)
        print(folder, {k: round(v, 3) if isinstance(v, float) else v
                       for k, v in figures.items()}, flush=True)
        if args.splits:
            figures["cross_object_fits"] = cross_object_fits(
                data, args.holdout_objects, args.splits, args.updates, args.object_fractions)
    write_json(args.out, report)


if __name__ == "__main__":
    main()
