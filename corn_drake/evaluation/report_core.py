"""The keys every evaluation report shares, computed one way from its rows (episode_rows.py):
a policy's (episodes.evaluate), the 6D expert's (planner_episodes.report_of) and a merge of
parts (report_merge.py). Each adds its own beside them: a policy its action step and a
student's tracking; the expert its decisions and their costs.

The task's success (the paper's rule: within tolerance at any policy period) with its 95 %
Wilson interval, the successes that ended at rest beside it, HACMan's criterion where the rows
measured it (the expert's), per object and balanced over objects, why the other episodes
failed, and which of the requested episodes the rows hold.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from corn_drake.evaluation.episode_rows import wilson
from corn_drake.evaluation.failures import failure_counts, successes_ending_still


def episode_report(rows: list[dict], requested) -> dict:
    """The shared keys of the report of `rows` (sorted by episode), the episodes of `requested`
    (a range or sorted list of k): complete when every requested episode has its row."""
    per_object = defaultdict(list)
    for r in rows:
        per_object[r["object"]].append(r["success"])
    rates = {o: float(np.mean(s)) for o, s in per_object.items()}
    n, k = len(rows), sum(bool(r["success"]) for r in rows)
    report = {"success_rate": float(k / n) if n else None,
              "success_wilson_95": wilson(k, n),
              "balanced_success_rate": float(np.mean(list(rates.values()))) if rates else None,
              "per_object": rates,
              "mean_episode_length": float(np.mean([r["steps"] for r in rows])) if n else None,
              "failure_counts": failure_counts(rows),
              "successes_ending_still": successes_ending_still(rows)}
    if rows and all("hacman_success" in r for r in rows):
        report["hacman_success_rate"] = float(np.mean([r["hacman_success"] for r in rows]))
    requested = list(requested)
    report.update({"episodes_from": min(requested, default=0),
                   "episodes_requested": len(requested),
                   "complete": {r["episode"] for r in rows} >= set(requested),
                   "episodes": rows})
    return report
