"""Choosing by an ensemble of outcome models, pessimistically or not: README.md's item 38.

    .venv/bin/python docs/results/primitive/outcome_ensemble.py \
        models/weights/push_turn_primitive --data runs/big_collect runs/sources_all \
        --holdout-objects 40 --splits 3 --members 5 \
        --out docs/results/primitive/outcome_ensemble.json

A model of the primitives' outcomes fitted on a few dozen objects is confidently wrong on
others (item 37), and a choice by the highest predicted reward among hundreds of candidates
picks exactly the candidates it is most wrong about. Per split, `--holdout-objects` objects are
held out whole; `--members` outcome models (rl/outcome_model.fit_model, seeds apart) are fitted
to the first `--object-fractions` of the others; every held-out state's choice is then scored in
the rewards the simulator measured (lookahead_distill.scores_quality's `chosen`), choosing by:
  single        the first member's predicted reward (what a shipped outcome run does),
  mean          the members' mean,
  lcb_K         the mean less K times the members' standard deviation (pessimism),
  lcb_K_or_policy  lcb_K's candidate where its bound is above 0 (the bound expects progress),
                the policy's own candidate (each state's first) otherwise;
beside `first` (the policy's own candidate), `best` (the lookahead's) and `mean` (a random
candidate). Data from several folders whose object ids coincide (libraries of other seeds) are
told apart by the folder's position: "1:block_000".
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from distill_scaling import held_out_objects, select_states  # noqa: E402
from lookahead_distill import load_data  # noqa: E402

from corn_drake.rl.primitive.outcome.lookahead_distill import scores_quality  # noqa: E402
from corn_drake.rl.primitive.outcome.model import (OUTCOME_KEYS, OUTCOME_ROW_KEYS,  # noqa: E402
                                         data_candidates, fit_model, model_inputs,
                                         predicted_rewards)
from corn_drake.rl.primitive.agent import load_primitive_run  # noqa: E402
from corn_drake.rl.primitive.outcome.tilt_classifier import (box_contact_features, data_tilted,  # noqa: E402
                                           fit_tilt_classifier)
from corn_drake.storage.atomic_files import write_json  # noqa: E402

PESSIMISM = (0.5, 1.0, 2.0)
TILT_VETO = (0.2, 0.5)  # the classifier's probability of a tilt above which a candidate is out


def load_folders(folders: list[Path]) -> dict:
    """The folders' data as one dict, each object id prefixed by its folder's position."""
    files, tags = [], []
    for i, folder in enumerate(folders):
        found = sorted(folder.glob("episodes_*.npz"))
        if not found:
            raise SystemExit(f"--data {folder}: no episodes_*.npz files")
        files += found
        tags += [f"{i}:"] * len(found)
    data = load_data(files, tags)
    missing = [k for k in ("object", *OUTCOME_KEYS, *OUTCOME_ROW_KEYS) if k not in data]
    if missing:
        raise SystemExit(f"--data {' '.join(map(str, folders))}: files without "
                         f"{', '.join(missing)}")
    return data


def load_study(run, folders: list[Path], holdout_objects: int):
    """(the run's config, the folders' data, their objects) for a held-out-objects study, or
    SystemExit when fewer objects than `holdout_objects` would be left to fit on."""
    base, _, _ = load_primitive_run(run)
    data = load_folders(folders)
    objects = sorted(set(data["object"]))
    if holdout_objects >= len(objects):
        raise SystemExit(f"--holdout-objects {holdout_objects}: the data have only "
                         f"{len(objects)} objects")
    return base, data, objects


def member_rewards(models: list, data: dict, task, progress_reward: float) -> np.ndarray:
    """(rows, members) each member's predicted reward of every candidate."""
    candidates = data_candidates(data)
    x, now, frames = model_inputs(candidates, tokens=False)
    with torch.no_grad():
        return np.stack([predicted_rewards(candidates, frames, m(x, now), task, progress_reward)
                         for m in models], 1)


def quality(scores: np.ndarray, data: dict, tilted: np.ndarray) -> dict:
    """scores_quality's figures, and the share of states whose chosen candidate tilted."""
    chosen = [rows[np.argmax(scores[rows])] for rows in _state_rows(data)]
    return {**scores_quality(scores, data), "chosen_tilted": float(tilted[chosen].mean())}


def _state_rows(data: dict) -> list[np.ndarray]:
    order = np.argsort(data["state"], kind="stable")
    return np.split(order, np.flatnonzero(np.diff(data["state"][order])) + 1)


def vetoed(scores: np.ndarray, data: dict, veto: np.ndarray) -> np.ndarray:
    """`scores` with the vetoed candidates ranked below every other of their state (a state
    whose every candidate is vetoed keeps its order)."""
    out = scores.copy()
    for rows in _state_rows(data):
        if not veto[rows].all():
            out[rows[veto[rows]]] = -np.inf
    return out


def choices(rewards: np.ndarray, data: dict, tilt_logits: np.ndarray) -> dict:
    """quality's figures of every way of choosing (module docstring)."""
    tilted = data_tilted(data)
    mean, spread = rewards.mean(1), rewards.std(1)
    out = {"single": quality(rewards[:, 0], data, tilted), "mean": quality(mean, data, tilted)}
    first = np.zeros(len(mean), bool)
    first[np.unique(data["state"], return_index=True)[1]] = True  # each state's first row
    for k in PESSIMISM:
        bound = mean - k * spread
        out[f"lcb_{k:g}"] = quality(bound, data, tilted)
        # Per state: the bound's best if it expects progress, else the policy's own candidate.
        fallback = bound.copy()
        for rows in _state_rows(data):
            if bound[rows].max() <= 0.0:
                fallback[rows] = np.where(first[rows], 1.0, 0.0)
        out[f"lcb_{k:g}_or_policy"] = quality(fallback, data, tilted)
    for name, scores in (("single", rewards[:, 0]), ("lcb_1", mean - spread)):
        out[f"{name}_true_tilt_veto"] = quality(vetoed(scores, data, tilted), data, tilted)
        for p in TILT_VETO:
            veto = tilt_logits > np.log(p / (1 - p))
            out[f"{name}_tilt_veto_{p:g}"] = quality(vetoed(scores, data, veto), data, tilted)
    out["policy"] = quality(first.astype(float), data, tilted)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", help="the primitive run whose task and progress reward score")
    parser.add_argument("--data", type=Path, nargs="+", required=True)
    parser.add_argument("--holdout-objects", type=int, default=40)
    parser.add_argument("--splits", type=int, default=3)
    parser.add_argument("--members", type=int, default=5)
    parser.add_argument("--updates", type=int, default=2000)
    parser.add_argument("--object-fractions", type=float, nargs="+", default=[1.0])
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    torch.set_num_threads(1)
    base, data, objects = load_study(args.run, args.data, args.holdout_objects)
    task, progress = base.env.task, base.primitive.progress_reward
    report = {"run": str(args.run), "data": [str(d) for d in args.data],
              "states": int(len(data["features_tokens"])), "rows": int(len(data["reward"])),
              "objects": len(objects), "holdout_objects": args.holdout_objects,
              "members": args.members, "updates": args.updates, "fits": []}
    for split in range(args.splits):
        held, rest = held_out_objects(objects, args.holdout_objects, split)
        held_out = select_states(data, np.flatnonzero(np.isin(data["object"], held)))
        for fraction in args.object_fractions:
            used = rest[:max(1, round(fraction * len(rest)))]
            train = select_states(data, np.flatnonzero(np.isin(data["object"], used)))
            models = [fit_model(train, False, args.updates, 100 * split + m)
                      for m in range(args.members)]
            classifier = fit_tilt_classifier(box_contact_features(data_candidates(train)),
                                             data_tilted(train), args.updates, split)
            with torch.no_grad():
                logits = classifier(box_contact_features(data_candidates(held_out))).numpy()
            row = {"split": split, "train_objects": len(used),
                   "train_states": int(len(train["features_tokens"])),
                   "held_out_states": int(len(held_out["features_tokens"])),
                   "held_out": choices(member_rewards(models, held_out, task, progress),
                                       held_out, logits)}
            report["fits"].append(row)
            write_json(args.out, report)
            h = row["held_out"]
            print(f"split {split}, {len(used)} objects: best {h['single']['best']:.3f} policy "
                  f"{h['single']['first']:.3f} single {h['single']['chosen']:.3f} mean "
                  f"{h['mean']['chosen']:.3f} " + " ".join(
                      f"{name} {h[name]['chosen']:.3f} ({h[name]['chosen_tilted']:.2f})"
                      for name in h if name not in ("single", "mean")), flush=True)


if __name__ == "__main__":
    main()
