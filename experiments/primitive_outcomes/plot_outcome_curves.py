"""Draws outcome_curves.png, the learning curves of the shipped full6d policy
(`models/weights/full6d_outcome`, experiments/primitive_policy/LOG.md's item 40): its outcome model's fit (the Huber loss
of the batches, from the folder's training_history.json) and success on the 200 unseen episodes
against the training objects the model was fitted on, every fit seed a point.

    .venv/bin/python -m experiments.primitive_outcomes.plot_outcome_curves

The points are docs/results/primitive's evaluate reports (--results): `eval_{task}_outcome_objects{N}_seed{S}.json`
(`corn-drake fit-outcome --objects N --seed S`) and, for all 218 objects, the five fits of item 39
(`eval_{task}_outcome_big{,_seed1,...}.json`), and as triangles beside them the five fits of the
model reading object-relative inputs (`eval_{task}_outcome_box_contact_seed{S}.json`, `fit-outcome
--inputs box_contact`; the shipped one is seed 0). The left panel is the shipped model's fit.
A missing report is named in one line.
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

REPO = Path(__file__).resolve().parents[2]
RESULTS = REPO / "docs" / "results" / "primitive"
HISTORY = REPO / "models" / "weights" / "full6d_outcome" / "training_history.json"
ALL_OBJECTS = 218  # runs/big_collect's 161 and runs/sources_all's 57
SUBSETS, SUBSET_SEEDS = (27, 54, 109), (0, 1)
TASKS = {"full6d": "tab:green", "push_turn": "tab:orange"}


def reports(results: Path, task: str) -> dict[int, list[Path]]:
    """Training objects -> that many objects' reports, one per fit seed."""
    out = {n: [results / f"eval_{task}_outcome_objects{n}_seed{s}.json" for s in SUBSET_SEEDS]
           for n in SUBSETS}
    out[ALL_OBJECTS] = [results / f"eval_{task}_outcome_big{suffix}.json"
                        for suffix in ("", "_seed1", "_seed2", "_seed3", "_seed4")]
    return out


def rates(paths: list[Path]) -> list[float]:
    """The reports' success rates, or SystemExit naming the first report missing."""
    missing = [p.name for p in paths if not p.is_file()]
    if missing:
        raise SystemExit(f"plot_outcome_curves.py: {missing[0]} is missing (experiments/primitive_policy/LOG.md's "
                         "item 40 commands make it)")
    return [json.loads(p.read_text())["success_rate"] for p in paths]


def box_reports(results: Path, task: str) -> list[Path]:
    """The five fits of the model reading box_contact_features, on all 218 objects."""
    return [results / f"eval_{task}_outcome_box_contact_seed{s}.json" for s in range(5)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=RESULTS,
                        help="the folder of the evaluate reports; the figure is written there")
    parser.add_argument("--history", type=Path, default=HISTORY,
                        help="the shipped outcome folder's training_history.json")
    args = parser.parse_args()
    history = json.loads(args.history.read_text())["history"]
    if not history:
        sys.exit(f"plot_outcome_curves.py: {args.history} has no rows (a model file from before "
                 "fits recorded them)")
    fig = Figure(figsize=(9, 3.2))
    fit, success = fig.subplots(1, 2)
    fit.plot([r["update"] for r in history], [r["huber_loss"] for r in history])
    fit.set(xlabel="updates (256 candidates each)", ylabel="Huber loss (training batches)",
            title="the shipped model's fit")
    for task, colour in TASKS.items():
        found = {n: rates(paths) for n, paths in reports(args.results, task).items()}
        sizes = sorted(found)
        for n in sizes:
            success.plot([n] * len(found[n]), found[n], "o", color=colour, alpha=0.45, ms=4)
        success.plot(sizes, [np.mean(found[n]) for n in sizes], "-", color=colour,
                     label=f"{task} (mean of the fits)")
        box = rates(box_reports(args.results, task))
        success.plot([ALL_OBJECTS * 1.08] * len(box), box, "^", color=colour, ms=5,
                     label=f"{task}, object-relative inputs (box_contact)")
    success.set_xscale("log", base=2)
    success.minorticks_off()
    sizes = [*SUBSETS, ALL_OBJECTS]
    success.set_xticks(sizes, [str(n) for n in sizes])
    success.set(xlabel="training objects (log scale)", ylabel="success, 200 unseen episodes",
                ylim=(0, 0.5), title="success against objects")
    success.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(args.results / "outcome_curves.png", dpi=100)
    print(f"wrote {args.results / 'outcome_curves.png'}")


if __name__ == "__main__":
    main()
