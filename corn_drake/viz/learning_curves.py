"""Learning curves of training runs: success and return against env steps or training hours,
and the comparison of runs at an equal training time.

A run's history rows (rl/training/ppo_trainer.py) carry each update's env steps and the steps/s
it ran at, so the wall-clock a run spent training is the sum of steps / rate over its updates: the time
of the updates only (no start-up, nothing between a kill and the resume), as measured on the
machine the run went on ("recorded"). On a machine whose one core is shared now and then (an
evaluation beside the run halves its rate for a while), the run's median rate is the steadier
measure ("median"), and a same-run benchmark of every policy on a quiet machine (`corn-drake
bench policies`) the fairest: a number of steps/s charges every update at that rate. The paper
compares representations at equal steps and at equal time (its two panels); `corn-drake curves
--x hours` draws the second.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from corn_drake.contract import RECENT_EPISODES

X_AXES = ("steps", "hours")
RATES = ("median", "recorded")


def training_hours(history: list[dict], rate: str | float = "median") -> np.ndarray:
    """Cumulative training hours at each history row (rows in step order), each update charged
    at its recorded steps/s, at the run's median steps/s, or at `rate` steps/s (a number)."""
    if isinstance(rate, str) and rate not in RATES:
        raise ValueError(f"rate must be one of {RATES} or steps/s, got {rate!r}")
    if not isinstance(rate, str) and not rate > 0:
        raise ValueError(f"a rate in steps/s must be > 0, got {rate}")
    steps = np.array([h["step"] for h in history], dtype=float)
    rates = np.array([h["steps_per_s"] for h in history], dtype=float)
    if np.any(~(rates > 0)) or np.any(np.diff(steps) <= 0):
        raise ValueError("history rows need increasing steps and positive steps_per_s")
    if rate == "median":
        rates = np.full_like(rates, np.median(rates))
    elif not isinstance(rate, str):
        rates = np.full_like(rates, float(rate))
    per_update = np.diff(steps, prepend=0.0)
    return np.cumsum(per_update / rates) / 3600.0


def first_full_window(history: list[dict]) -> int:
    """Index of the first row whose success rate averages a full window of episodes.

    Rows before the first finished episode hold placeholder zeros, and those before the window
    holds RECENT_EPISODES episodes average over the few that ended first — mostly early
    successes, since a success ends an episode. Curves start at a full window (or, for runs that never fill it,
    at the first finished episode)."""
    done = np.cumsum([h["episodes"] for h in history])
    full = np.flatnonzero(done >= RECENT_EPISODES)
    if len(full):
        return int(full[0])
    return int(np.argmax(done > 0)) if len(done) and done[-1] else len(history)


def rate_of(rates: Mapping[str, str | float] | str | float, label: str) -> str | float:
    """The rate a run is charged at: one for all runs, or per run label."""
    return rates[label] if isinstance(rates, Mapping) else rates


def at_equal_time(runs: dict[str, list[dict]],
                  rates: Mapping[str, str | float] | str | float = "median") -> dict:
    """Each run at the training time of the run that trained for the least: the step it had
    reached and its training success there (the last 100 training episodes, the curve's
    value). The time is the shortest run's, so every run has a row at or before it."""
    hours = {label: training_hours(h, rate_of(rates, label)) for label, h in runs.items() if h}
    if not hours:
        return {"hours": 0.0, "runs": {}}
    budget = min(float(t[-1]) for t in hours.values())
    rows = {}
    for label, t in hours.items():
        i = int(np.searchsorted(t, budget, side="right")) - 1
        row = runs[label][max(i, 0)]
        rows[label] = {"step": int(row["step"]), "hours": float(t[max(i, 0)]),
                       "rate": rate_of(rates, label),
                       "training_success_rate": float(row["success_rate"]),
                       "final_step": int(runs[label][-1]["step"]),
                       "final_hours": float(t[-1])}
    return {"hours": budget, "runs": rows}


def plot_learning_curves(runs: dict[str, list[dict]], path: Path, x: str = "steps",
                         rates: Mapping[str, str | float] | str | float = "median",
                         steps: str = "env steps") -> None:
    """Success rate and return against env steps or training hours, one line per run
    (label -> history rows); `steps` names what a row's step counts (a primitive run's are
    primitives)."""
    if x not in X_AXES:
        raise ValueError(f"x must be one of {X_AXES}, got {x!r}")
    # A Figure of its own, not pyplot: writing the file leaves the process's backend alone,
    # so a notebook that trains in its kernel keeps plotting inline.
    from matplotlib.figure import Figure
    from matplotlib.ticker import EngFormatter

    from corn_drake.storage.atomic_files import atomic_path

    runs = {label: history for label, history in runs.items() if history}
    if not runs:
        return
    fig = Figure(figsize=(9, 3.2))
    axes = fig.subplots(1, 2)
    for label, history in runs.items():
        xs = (training_hours(history, rate_of(rates, label)) if x == "hours"
              else np.array([h["step"] for h in history]))
        first = first_full_window(history)
        history, xs = history[first:], xs[first:]
        axes[0].plot(xs, [h["success_rate"] for h in history], label=label)
        axes[1].plot(xs, [h["return"] for h in history], label=label)
    kinds = {str(r) for r in (rates.values() if isinstance(rates, Mapping) else [rates])}
    how = kinds.pop() if len(kinds) == 1 and kinds <= set(RATES) else "benchmarked"
    xlabel = f"training hours ({how} steps/s, this machine)" if x == "hours" else steps
    axes[0].set(xlabel=xlabel, ylabel="success rate (last 100 episodes)", ylim=(0, 1))
    axes[1].set(xlabel=xlabel, ylabel="episode return")
    if x == "steps":
        for ax in axes:
            ax.xaxis.set_major_formatter(EngFormatter())  # 100k, 1M: full step counts overlap
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
