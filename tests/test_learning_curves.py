"""Learning curves against training hours, and runs compared at an equal training time."""

import json
from argparse import Namespace

import numpy as np
import pytest

from corn_drake.viz.learning_curves import at_equal_time, plot_learning_curves, training_hours


def _history(rates, steps_per_update=3600, success=None):
    success = success or [0.1 * (i + 1) for i in range(len(rates))]
    return [{"step": steps_per_update * (i + 1), "steps_per_s": r, "episodes": 100,
             "success_rate": s, "return": s} for i, (r, s) in enumerate(zip(rates, success))]


def test_training_hours_sum_each_updates_steps_over_its_rate():
    # 3600 steps at 1, 2 and 4 steps/s: 1 h, then 0.5 h, then 0.25 h as recorded; at the median
    # rate (2 steps/s) half an hour each.
    history = _history([1.0, 2.0, 4.0])
    np.testing.assert_allclose(training_hours(history, "recorded"), [1.0, 1.5, 1.75])
    np.testing.assert_allclose(training_hours(history, "median"), [0.5, 1.0, 1.5])
    with pytest.raises(ValueError, match="positive steps_per_s"):
        training_hours(_history([1.0, 0.0]))
    with pytest.raises(ValueError, match="rate must be"):
        training_hours(history, "mean")


def test_runs_at_equal_time_are_read_at_the_shortest_runs_hours():
    fast = _history([2.0] * 4, success=[0.1, 0.2, 0.3, 0.4])  # 0.5 h per update, 2 h in all
    slow = _history([1.0] * 3, success=[0.5, 0.6, 0.7])  # 1 h per update, 3 h in all
    equal = at_equal_time({"fast": fast, "slow": slow}, "recorded")
    assert equal["hours"] == pytest.approx(2.0)
    assert equal["runs"]["fast"]["step"] == 4 * 3600
    assert equal["runs"]["fast"]["training_success_rate"] == pytest.approx(0.4)
    # The slow run at 2 h: its second update (2 h), not its last (3 h).
    assert equal["runs"]["slow"]["step"] == 2 * 3600 and equal["runs"]["slow"]["hours"] == 2.0
    assert equal["runs"]["slow"]["training_success_rate"] == pytest.approx(0.6)
    assert equal["runs"]["slow"]["final_step"] == 3 * 3600


def test_curves_against_hours_write_the_figure_and_summary(tmp_path):
    from corn_drake.commands import curves
    from corn_drake.errors import InputError
    from corn_drake.io_utils import write_json

    for name, rates in (("a", [2.0] * 4), ("b", [1.0] * 3)):
        (tmp_path / name).mkdir()
        write_json(tmp_path / name / "metrics.json", {"history": _history(rates)})
    png, summary = tmp_path / "t.png", tmp_path / "out" / "s.json"
    assert curves.run(Namespace(runs=[str(tmp_path / "a"), str(tmp_path / "b")], out=str(png),
                                x="hours", rate="median", summary=str(summary))) == 0
    assert png.stat().st_size > 1000
    rows = json.loads(summary.read_text())["runs_at_equal_time"]["runs"]
    assert {r["step"] for r in rows.values()} == {4 * 3600, 2 * 3600}
    write_json(tmp_path / "a" / "metrics.json", {"history": _history([2.0, -1.0])})
    with pytest.raises(InputError, match="no training time"):
        curves.run(Namespace(runs=[str(tmp_path / "a")], out=str(png), x="hours", rate="median",
                             summary=""))
    with pytest.raises(ValueError, match="x must be"):
        plot_learning_curves({"a": _history([1.0])}, png, x="minutes")
