"""`corn-drake bench planner`: the 6D expert's simulated primitives per CPU second against bare
physics of the very same primitives, replayed in the same run."""

import json

import pytest

from corn_drake.cli import main


def test_the_expert_and_its_bare_replay_time_the_same_primitives(tmp_path):
    path = tmp_path / "planner.json"
    assert main(["bench", "planner", "--decisions", "2", "--set",
                 "planner.random_motions=0", "--set", "planner.depth=1", "--set",
                 "planner.sources=[policy, push]", "--report", str(path)]) == 0
    results = json.loads(path.read_text())["results"]
    # Depth 1: one expansion per decision, the policy's usable locations and up to 2 pushes.
    assert 2 <= results["simulated"] <= 2 * (16 + 2)
    assert results["simulated_per_decision"] == results["simulated"] / 2
    assert results["search_to_bare"] == pytest.approx(
        results["bare_primitives_per_cpu_s"] / results["search_primitives_per_cpu_s"], rel=1e-9)
    assert results["decisions_per_core_hour"] == pytest.approx(
        3600 / results["cpu_seconds_per_decision"], rel=1e-9)
    assert results["planner"]["sources"] == ["policy", "push"] and results["task"] == "full6d"


def test_a_bad_setting_is_refused_before_anything_runs(tmp_path, capsys):
    path = tmp_path / "planner.json"
    assert main(["bench", "planner", "--set", "planner.depth=9", "--report", str(path)]) == 2
    assert "planner.depth must be" in capsys.readouterr().err and not path.exists()
