"""Draws hindsight_curves.png: training success of the push_turn and full6d runs started from the
push policy, with hindsight goals (items 13-18 of experiments/primitive_policy/LOG.md) and without (the table's rows); and
variant_curves.png: the variants of the low-push hindsight run on push_turn (items 19-23, 27, 30).

    .venv/bin/python -m experiments.primitive_policy.plot_hindsight_curves

Reads docs/results/primitive's train_history_<name>.json files (--results; each {"run",
"primitives", "history": rows of the trainer's metrics}); writes the figures next to them.
"""

import argparse
import json
from pathlib import Path

from matplotlib.figure import Figure

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results" / "primitive"
RUNS = {  # label -> history file, drawn in this order (same colour per task, dashed: no hindsight)
    "push_turn": ("train_history_push_turn.json", "tab:orange", "--"),
    "push_turn + hindsight goals": ("train_history_push_turn_hindsight.json", "tab:orange", "-"),
    "push_turn + hindsight goals, low pushes": ("train_history_push_turn_hindsight_low_push.json",
                                                "tab:red", "-"),
    "push_turn + hindsight goals, from scratch": (
        "train_history_push_turn_hindsight_from_scratch.json", "tab:purple", "-"),
    "push_turn from scratch": ("train_history_push_turn_from_scratch.json", "tab:purple", "--"),
    "full6d": ("train_history_full6d.json", "tab:green", "--"),
    "full6d + hindsight goals": ("train_history_full6d_hindsight.json", "tab:green", "-"),
    "full6d + hindsight goals, 10 cm pushes": ("train_history_full6d_hindsight_short_push.json",
                                               "tab:olive", "-"),
    "full6d + hindsight goals, 10 cm pushes, kept on the table": (
        "train_history_full6d_hindsight_short_push_keep_on_table.json", "tab:olive", ":"),
}

VARIANTS = {  # item 15's run and what items 19-23, 27 and 30 changed in it, each to 12,000 primitives
    "low pushes (item 15)": ("train_history_push_turn_hindsight_low_push.json", "tab:red", "-"),
    "64 point locations": ("train_history_push_turn_hindsight_point64.json", "tab:blue", "-"),
    "cloud-point reward": ("train_history_push_turn_hindsight_cloud_reward.json", "tab:green",
                           "-"),
    "no exit goals": ("train_history_push_turn_hindsight_no_exit_goals.json", "tab:gray", "-"),
    "no exit goals + exit penalty": ("train_history_push_turn_hindsight_exit_penalty.json",
                                     "tab:brown", "-"),
    "no exit goals + short pushes, 15 primitives": (
        "train_history_push_turn_hindsight_short_push.json", "tab:purple", "-"),
    "pushes kept on the table": ("train_history_push_turn_hindsight_keep_on_table.json",
                                 "tab:olive", "-"),
    "8-period pushes kept on the table": (
        "train_history_push_turn_hindsight_slow_push_keep_on_table.json", "tab:cyan", "-"),
}


def draw(results: Path, runs: dict, out: str, until: int | None = None) -> None:
    fig = Figure(figsize=(9, 3.2))
    success, q = fig.subplots(1, 2)
    for label, (name, colour, style) in runs.items():
        rows = [r for r in json.loads((results / name).read_text())["history"]
                if until is None or r["step"] <= until]
        steps = [r["step"] for r in rows]
        success.plot(steps, [r["success_rate"] for r in rows], style, color=colour, label=label)
        q.plot(steps, [r["q_mean"] if r["q_mean"] is not None else float("nan") for r in rows],
               style, color=colour, label=label)
    success.set(xlabel="primitives", ylabel="training success (exploring)",
                ylim=(0, 0.5))
    q.set(xlabel="primitives", ylabel="critic mean Q at taken locations")
    success.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(results / out, dpi=100)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=RESULTS,
                        help="the folder of the train_history files; the figures go there")
    args = parser.parse_args()
    draw(args.results, RUNS, "hindsight_curves.png")
    draw(args.results, VARIANTS, "variant_curves.png", until=12000)
    print(f"wrote {args.results / 'hindsight_curves.png'}, {args.results / 'variant_curves.png'}")


if __name__ == "__main__":
    main()
