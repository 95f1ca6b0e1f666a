"""The learned 6D chooser's success on the first 40 fixed episodes against the labels it was
fitted to (issue 61's curve), drawn from the committed evaluation reports:

    python experiments/expert_labels/label_curve.py

writes docs/results/planner/chooser_vs_labels.png. Each point is a report of
docs/results/planner/ whose `chooser_value` facts say how many labelled states the chooser was
fitted to (0: the proposing run's outcome model alone); the expert's own rate on the same
episodes is drawn as a line.
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

PAGE = Path(__file__).resolve().parents[2] / "docs" / "results" / "planner"
# (report, label) in the order measured; the prior is the 0-label point.
POINTS = [("eval_full6d_outcome_first40_here.json", "the prior alone"),
          ("eval_chooser_r0_stop_first40.json", "product fit"),
          ("eval_chooser_r1_stop_first40.json", "product fit"),
          ("eval_chooser_r1_listwise_first40.json", "study: listwise, no token")]


def main() -> None:
    fig, ax = plt.subplots(figsize=(6, 3.6))
    series: dict[str, list] = {}
    for name, label in POINTS:
        report = json.loads((PAGE / name).read_text())
        states = (report.get("chooser_value") or {}).get("states", 0)
        rate = sum(e["success"] for e in report["episodes"]) / len(report["episodes"])
        series.setdefault(label, []).append((states, rate))
    series["product fit"] = [series["the prior alone"][0], *series["product fit"]]
    for label, points in series.items():
        xs, ys = zip(*sorted(points))
        ax.plot(xs, ys, "o-" if len(xs) > 1 else "s", label=label)
    expert = json.loads((PAGE / "gate_a_policy_first40.json").read_text())["success_rate"]
    ax.axhline(expert, color="k", ls="--", lw=1, label=f"the expert ({expert:.3f})")
    ax.axhline(0.5, color="grey", ls=":", lw=1, label="issue 61's goal (200 episodes)")
    ax.set(xlabel="labelled states the chooser was fitted to", ylim=(0, 0.8),
           ylabel="success, first 40 episodes", title="learned 6D chooser against labels")
    ax.legend(fontsize=7)
    fig.tight_layout()
    out = PAGE / "chooser_vs_labels.png"
    fig.savefig(out, dpi=110)
    print(out)


if __name__ == "__main__":
    main()
