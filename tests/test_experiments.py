"""The studies kept in experiments/ run, each on a tiny input made here, the way their READMEs
say to run them (`python -m experiments.TOPIC.SCRIPT` from the repository root), so that a
change to the package they import cannot leave them broken unnoticed."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.test_outcome_commands import PROPOSING_RUN, write_chunk

REPO = Path(__file__).resolve().parents[1]
TOPICS = ("primitive_outcomes", "primitive_policy")


def _run(module: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    done = subprocess.run([sys.executable, "-m", module, *args], cwd=REPO, capture_output=True,
                          text=True, timeout=timeout)
    assert done.returncode == 0, done.stderr[-3000:]
    return done


@pytest.mark.parametrize("topic", TOPICS)
def test_every_topic_is_a_package_with_a_readme_naming_its_scripts(topic):
    folder = REPO / "experiments" / topic
    assert (folder / "__init__.py").is_file() and (REPO / "experiments" / "__init__.py").is_file()
    readme = (folder / "README.md").read_text()
    for script in folder.glob("*.py"):
        if script.name != "__init__.py":
            assert f"`{script.name}`" in readme, script.name


def test_no_study_edits_sys_path():
    for script in (REPO / "experiments").rglob("*.py"):
        assert "sys.path" not in script.read_text(), script


def test_scores_quality_takes_each_states_highest_scored_candidate():
    from experiments.primitive_outcomes.held_out import scores_quality

    data = {"state": np.array([0, 0, 0, 1, 1]),
            "reward": np.array([0.1, 0.5, -0.2, 0.0, 0.3])}
    figures = scores_quality(np.array([3.0, 1.0, 2.0, -1.0, 5.0]), data)
    assert figures["chosen"] == pytest.approx((0.1 + 0.3) / 2)
    assert figures["best"] == pytest.approx((0.5 + 0.3) / 2)
    assert figures["first"] == pytest.approx((0.1 + 0.0) / 2)
    assert figures["mean"] == pytest.approx((0.4 / 3 + 0.15) / 2)


def test_outcome_inputs_measures_every_input_kind_on_held_out_objects(tmp_path):
    folders = [tmp_path / "a", tmp_path / "b"]
    for i, folder in enumerate(folders):
        folder.mkdir()
        write_chunk(folder / "episodes_00000.npz", 4, ["box_00", "cyl_01"], seed=i)
    out = tmp_path / "inputs.json"
    _run("experiments.primitive_outcomes.outcome_inputs", str(PROPOSING_RUN), "--data",
         *map(str, folders), "--holdout-objects", "1", "--splits", "2", "--updates", "5",
         "--out", str(out))
    report = json.loads(out.read_text())
    assert report["objects"] == 4 and len(report["splits"]) == 2
    for key in ("keypoint_error_m", "chosen"):
        assert set(report["mean"][key]) == {"raw", "raw_and_box", "box_contact"}
        assert all(np.isfinite(v) for v in report["mean"][key].values())


def test_plot_outcome_curves_draws_from_the_reports(tmp_path):
    from experiments.primitive_outcomes import plot_outcome_curves as plot

    rng = np.random.default_rng(0)
    for task in plot.TASKS:
        paths = [p for group in plot.reports(tmp_path, task).values() for p in group]
        for path in [*paths, *plot.box_reports(tmp_path, task)]:
            path.write_text(json.dumps({"success_rate": float(rng.uniform(0, 0.4))}))
    history = tmp_path / "training_history.json"
    history.write_text(json.dumps({"history": [{"update": 100, "huber_loss": 0.5},
                                               {"update": 200, "huber_loss": 0.3}]}))
    _run("experiments.primitive_outcomes.plot_outcome_curves", "--results", str(tmp_path),
         "--history", str(history))
    assert (tmp_path / "outcome_curves.png").stat().st_size > 1000


def test_plot_hindsight_curves_draws_from_the_histories(tmp_path):
    from experiments.primitive_policy import plot_hindsight_curves as plot

    for name, _, _ in [*plot.RUNS.values(), *plot.VARIANTS.values()]:
        rows = [{"step": s, "success_rate": s / 24000, "q_mean": None if s == 0 else 0.1}
                for s in (0, 6000, 12000)]
        (tmp_path / name).write_text(json.dumps({"history": rows}))
    _run("experiments.primitive_policy.plot_hindsight_curves", "--results", str(tmp_path))
    for figure in ("hindsight_curves.png", "variant_curves.png"):
        assert (tmp_path / figure).stat().st_size > 1000
