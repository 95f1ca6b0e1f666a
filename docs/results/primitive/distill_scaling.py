"""How the distilled critic's choices on unseen objects grow with the lookahead data: README.md's
item 35.

    .venv/bin/python docs/results/primitive/distill_scaling.py \
        models/weights/push_turn_primitive --data runs/lookahead_data runs/outcome_data1 \
        runs/outcome_data2 --out docs/results/primitive/distill_scaling.json

The data are `lookahead_distill.py collect` folders (every state's features and every candidate's
measured reward; each state's object). Each split holds out `--holdout-objects` training objects
whole: their states are never fitted, only chosen among, so the held-out figure is what the
critic does on objects it has not seen, as the 200 evaluation episodes ask. For every fraction of
the remaining objects (nested: a larger fraction adds objects), the run's critic is fitted
afresh from its shipped weights with the rank loss (rl/lookahead_distill.fit_critic) for the
same number of updates, and its choice among each held-out state's candidates is scored in the
rewards the simulator measured (choice_quality: `chosen`; `best` is the lookahead's, `first` the
collecting policy's own, `mean` a random candidate's). The report is rewritten atomically after
every fit.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lookahead_distill import load_data  # noqa: E402 - the collect folders' reader

from corn_drake.rl.primitive.outcome.lookahead_distill import choice_quality, fit_critic  # noqa: E402
from corn_drake.rl.primitive.agent import load_primitive_run  # noqa: E402
from corn_drake.storage.atomic_files import write_json  # noqa: E402

BATCH_ROWS = 256  # rows per update (whole states, fit_critic's rank batches)


# The data's per-candidate arrays (rl/lookahead_distill.stack_states; the last three only in
# data collected with their outcomes); every other array but "state" has one entry per state.
ROW_KEYS = ("location", "motion", "reward", "pose_after", "still_after", "success_after")


def select_states(data: dict, states: np.ndarray) -> dict:
    """The data of `states` (state indices), their candidates' rows with them, state indices
    renumbered 0..len-1."""
    states = np.sort(np.asarray(states))
    number = np.full(len(data["features_tokens"]), -1, np.int64)
    number[states] = np.arange(len(states))
    rows = np.flatnonzero(number[data["state"]] >= 0)
    out = {k: v[rows] if k in ROW_KEYS else v[states] for k, v in data.items() if k != "state"}
    out["state"] = number[data["state"][rows]]
    return out


def trend(fits: list[dict]) -> dict | None:
    """The least-squares line of the held-out `chosen` against log2(training states), over
    every fit so far, and where it would meet the lookahead's own figure (the mean held-out
    `best`): an extrapolation, far outside the measured sizes, to size the next data
    collection, not a prediction."""
    sizes = sorted({f["train_states"] for f in fits})
    if len(sizes) < 2:
        return None
    x = np.log2([f["train_states"] for f in fits])
    y = np.array([f["held_out"]["chosen"] for f in fits])
    slope, intercept = np.polyfit(x, y, 1)
    best = float(np.mean([f["held_out"]["best"] for f in fits]))
    reach = float(2 ** ((best - intercept) / slope)) if slope > 0 else None
    return {"chosen_per_doubling": float(slope), "chosen_at_1_state": float(intercept),
            "held_out_best": best, "states_where_the_line_meets_best": reach}


def study_arguments(description: str) -> argparse.ArgumentParser:
    """The arguments this study and outcome_model.py share."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("run")
    parser.add_argument("--data", type=Path, nargs="+", required=True)
    parser.add_argument("--holdout-objects", type=int, default=12)
    parser.add_argument("--splits", type=int, default=3)
    parser.add_argument("--updates", type=int, default=2000,
                        help="rank-fit (and model) updates per fit, whatever its data's size")
    parser.add_argument("--out", type=Path, required=True)
    return parser


def load_study_data(folders: list[Path], holdout_objects: int,
                    needed: tuple[str, ...] = (), tag_folders: bool = False
                    ) -> tuple[dict, list[str]]:
    """(the folders' data, their objects), or SystemExit naming what is missing. With
    `tag_folders` each object id is prefixed by its folder's position ("1:block_000"):
    libraries of other seeds reuse the ids."""
    files = sorted(f for folder in folders for f in folder.glob("episodes_*.npz"))
    tags = [f"{folders.index(f.parent)}:" for f in files] if tag_folders else None
    data = load_data(files, tags) if files else {}
    missing = [k for k in ("object", *needed) if k not in data]
    if missing:
        raise SystemExit(f"--data {' '.join(map(str, folders))}: no episodes_*.npz files, or "
                         f"files without {', '.join(missing)} (collected before they were "
                         "stored)")
    objects = sorted(set(data["object"]))
    if holdout_objects >= len(objects):
        raise SystemExit(f"--holdout-objects {holdout_objects}: the data have only "
                         f"{len(objects)} objects")
    return data, objects


def held_out_objects(objects: list[str], count: int, split: int) -> tuple[list, list]:
    """(held-out objects, the others in a split's own order): split k's seeded shuffle."""
    order = list(np.random.default_rng(split).permutation(objects))
    return order[:count], order[count:]


def main() -> None:
    parser = study_arguments(__doc__.splitlines()[0])
    parser.add_argument("--fractions", type=float, nargs="+", default=[0.125, 0.25, 0.5, 1.0])
    parser.add_argument("--epochs", type=int, default=0,
                        help="epochs per fit instead of --updates (0: --updates): the same "
                             "passes over the data whatever its size")
    args = parser.parse_args()
    torch.set_num_threads(1)
    data, objects = load_study_data(args.data, args.holdout_objects)
    report = {"run": args.run, "data": [str(d) for d in args.data],
              "states": int(len(data["features_tokens"])), "rows": int(len(data["reward"])),
              "objects": len(objects), "holdout_objects": args.holdout_objects,
              "updates": args.updates, "epochs": args.epochs, "fits": []}
    for split in range(args.splits):
        held, rest = held_out_objects(objects, args.holdout_objects, split)
        held_out = select_states(data, np.flatnonzero(np.isin(data["object"], held)))
        _, shipped, _ = load_primitive_run(args.run)
        before = choice_quality(shipped, held_out)
        for fraction in args.fractions:
            used = rest[:max(1, round(fraction * len(rest)))]
            train = select_states(data, np.flatnonzero(np.isin(data["object"], used)))
            _, agent, _ = load_primitive_run(args.run)
            per_epoch = math.ceil(len(train["reward"]) / BATCH_ROWS)
            epochs = args.epochs or max(1, round(args.updates / per_epoch))
            fit_critic(agent, train, epochs, batch_size=BATCH_ROWS, loss="rank", seed=split)
            row = {"split": split, "fraction": fraction, "train_objects": len(used),
                   "train_states": int(len(train["features_tokens"])),
                   "held_out_states": int(len(held_out["features_tokens"])), "epochs": epochs,
                   "held_out": choice_quality(agent, held_out),
                   "held_out_shipped_critic": before,
                   "train": choice_quality(agent, train)}
            report["fits"].append(row)
            report["trend"] = trend(report["fits"])
            write_json(args.out, report)
            print(f"split {split} objects {len(used)} states {row['train_states']}: held-out "
                  f"chosen {row['held_out']['chosen']:.3f} (shipped {before['chosen']:.3f}, "
                  f"best {before['best']:.3f}), train chosen {row['train']['chosen']:.3f}",
                  flush=True)


if __name__ == "__main__":
    main()
