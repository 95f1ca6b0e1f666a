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
    # A benchmarked rate (steps/s) charges every update at it: 3 x 3600 steps at 3 steps/s.
    np.testing.assert_allclose(training_hours(history, 3.0), [1 / 3, 2 / 3, 1.0])
    with pytest.raises(ValueError, match="must be > 0"):
        training_hours(history, 0.0)


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
    from corn_drake.commands.reporting import curves
    from corn_drake.errors import InputError
    from corn_drake.storage.atomic_files import write_json

    for name, rates in (("a", [2.0] * 4), ("b", [1.0] * 3)):
        (tmp_path / name).mkdir()
        write_json(tmp_path / name / "metrics.json", {"history": _history(rates)})
    png, summary, history = tmp_path / "t.png", tmp_path / "out" / "s.json", tmp_path / "h" / "h.json"
    assert curves.run(Namespace(runs=[str(tmp_path / "a"), str(tmp_path / "b")], out=str(png),
                                x="hours", rate="median", rates="", summary=str(summary),
                                history=str(history))) == 0
    assert png.stat().st_size > 1000
    rows = json.loads(summary.read_text())["runs_at_equal_time"]["runs"]
    assert {r["step"] for r in rows.values()} == {4 * 3600, 2 * 3600}
    # --history keeps every update's row of every run, with the run folder it came from.
    kept = json.loads(history.read_text())["runs"]
    assert {row["run"]: row["history"] for row in kept.values()} == {
        str((tmp_path / "a").resolve()): _history([2.0] * 4),
        str((tmp_path / "b").resolve()): _history([1.0] * 3)}
    with pytest.raises(InputError, match="--history"):  # refused before anything is plotted
        curves.run(Namespace(runs=[str(tmp_path / "a")], out=str(tmp_path / "u.png"), x="steps",
                             rate="median", rates="", summary="", history=str(png / "h.json")))
    assert not (tmp_path / "u.png").exists()
    write_json(tmp_path / "a" / "metrics.json", {"history": _history([2.0, -1.0])})
    with pytest.raises(InputError, match="no training time"):
        curves.run(Namespace(runs=[str(tmp_path / "a")], out=str(png), x="hours", rate="median", rates="",
                             summary="", history=""))
    with pytest.raises(ValueError, match="x must be"):
        plot_learning_curves({"a": _history([1.0])}, png, x="minutes")


def test_curves_charge_each_run_at_its_policys_benchmarked_rate(tmp_path, capsys):
    from corn_drake.cli import main
    from corn_drake.config.training import TrainConfig
    from corn_drake.storage.atomic_files import write_json
    from corn_drake.run_folders.config_file import write_run_config

    for name, policy in (("a", "corn"), ("b", "state")):
        (tmp_path / name).mkdir()
        write_json(tmp_path / name / "metrics.json", {"history": _history([1.0] * 4)})
        write_run_config(TrainConfig(policy=policy), tmp_path / name)
    rates = tmp_path / "policies.json"
    write_json(rates, {"benchmark": "policies",
                       "results": {"train_steps_per_s": {"corn": 2.0, "state": 4.0}}})
    summary = tmp_path / "s.json"
    assert main(["curves", "--run", str(tmp_path / "a"), "--run", str(tmp_path / "b"),
                 "--x", "hours", "--rates", str(rates), "--out", str(tmp_path / "c.png"),
                 "--summary", str(summary)]) == 0
    equal = json.loads(summary.read_text())["runs_at_equal_time"]
    # 4 x 3600 steps: corn at 2 steps/s takes 2 h, state at 4 steps/s 1 h.
    assert equal["hours"] == pytest.approx(1.0)
    rows = {row["run"]: row for row in equal["runs"].values()}
    assert rows[str((tmp_path / "a").resolve())]["step"] == 2 * 3600
    assert rows[str((tmp_path / "a").resolve())]["final_hours"] == pytest.approx(2.0)
    write_json(rates, {"benchmark": "policies", "results": {"train_steps_per_s": {"corn": 2.0}}})
    assert main(["curves", "--run", str(tmp_path / "b"), "--x", "hours", "--rates", str(rates),
                 "--out", str(tmp_path / "c.png")]) == 2
    assert "no rate for run" in capsys.readouterr().err
    for wrong in ({"benchmark": "train", "results": {}}, [1, 2]):
        write_json(rates, wrong)
        assert main(["curves", "--run", str(tmp_path / "b"), "--x", "hours", "--rates",
                     str(rates), "--out", str(tmp_path / "c.png")]) == 2
        assert "not a `corn-drake bench policies` report" in capsys.readouterr().err


def test_bench_policies_times_each_policy_on_the_same_envs(tmp_path, monkeypatch):
    from corn_drake.bench.training import timed_training
    from corn_drake.cli import main

    trained = []  # (policy, separate critic) of each trainer the benchmark ran
    original = timed_training.run_trainer

    def run_trainer(cfg, *args, **kwargs):
        trained.append((cfg.policy, cfg.ppo.separate_critic))
        return original(cfg, *args, **kwargs)

    monkeypatch.setattr(timed_training, "run_trainer", run_trainer)
    report = tmp_path / "p.json"
    assert main(["bench", "policies", "--policies", "state,corn", "--envs-per-worker", "2", "--updates", "1",
                 "--warmup-updates", "0", "--rollout-steps", "4", "--torch-threads", "1",
                 "--set", "ppo.separate_critic=false", "--report", str(report)]) == 0
    results = json.loads(report.read_text())["results"]
    assert results["torch_threads"] == 1 and results["ppo_sets"] == ["ppo.separate_critic=false"]
    assert trained == [("state", False), ("corn", False)]  # the --set reached every run
    assert set(results["train_steps_per_s"]) == {"state", "corn"}
    assert all(r > 0 for r in results["train_steps_per_s"].values())
    assert results["relative_to_reference"]["state"] == 1.0 and results["reference"] == "state"
