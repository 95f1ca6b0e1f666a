"""The command line: subcommand discovery and the sim benchmark's report."""

import json
from pathlib import Path

from corn_drake.cli import build_parser, main

# The push-from-behind task overlay (diagrams/tasks/push.yaml).
PUSH_TASK = "push"


def test_subcommands_are_discovered():
    text = build_parser().format_help()
    assert "bench" in text and "demo" in text


def test_bench_sim_writes_report_with_baseline(tmp_path):
    report = tmp_path / "sim.json"
    assert main(["bench", "sim", "--report", str(report), "--steps", "30"]) == 0
    data = json.loads(report.read_text())
    results = data["results"]
    for key in ("policy_steps_per_s", "bare_physics_policy_steps_per_s", "overhead_ratio",
                "physics_speedup"):
        assert results[key] > 0
    assert abs(results["overhead_ratio"] - results["bare_physics_policy_steps_per_s"]
               / results["policy_steps_per_s"]) < 1e-9
    assert abs(results["physics_speedup"] - results["configured_bare_physics_policy_steps_per_s"]
               / results["baseline_bare_physics_policy_steps_per_s"]) < 1e-9
    # The baseline is the previous defaults' file, read back as settings.
    assert results["baseline_physics"].endswith("previous_default.yaml")
    assert results["baseline_physics_settings"]["discrete_contact_approximation"] == "sap"
    assert "cpu_count" in data["machine"]


def test_bench_sim_compares_against_another_physics_overlay(tmp_path):
    """A baseline overlay with other contact settings is simulated with them (the lagged
    approximation here), and the report names both settings."""
    overlay = tmp_path / "lagged.yaml"
    overlay.write_text("scene: {physics: {plant: {discrete_contact_approximation: lagged}}}\n")
    report = tmp_path / "sim.json"
    assert main(["bench", "sim", "--report", str(report), "--steps", "20",
                 "--baseline-physics", str(overlay)]) == 0
    results = json.loads(report.read_text())["results"]
    assert results["baseline_physics_settings"]["discrete_contact_approximation"] == "lagged"
    assert results["physics"]["discrete_contact_approximation"] == "sap"
    assert results["physics_speedup"] > 0


def test_train_then_evaluate_writes_the_report_keys(tmp_path):
    run = tmp_path / "run"
    assert main(["train", "--policy", "state", "--steps", "64", "--envs-per-worker", "2",
                 "--rollout-steps", "16", "--set", "task.episode_steps=10", "--set",
                 "snapshot_every=32", "--out", str(run), "--no-progress"]) == 0
    report = tmp_path / "eval_state.json"
    assert main(["evaluate", "--run", str(run), "--episodes", "2", "--record", "1",
                 "--report", str(report)]) == 0
    data = json.loads(report.read_text())
    for key in ("success_rate", "balanced_success_rate", "per_object", "episodes", "env_steps"):
        assert key in data
    assert len(data["episodes"]) == 2 and 0.0 <= data["success_rate"] <= 1.0
    assert data["env_steps"] == 64 and data["checkpoint"] == "last.pt"
    html = data["episodes"][0]["recording"]
    assert html and Path(html).stat().st_size > 10_000
    # A kept snapshot evaluates as the run at its step; into the same report only with
    # --overwrite (its rows are another evaluation's: the weights differ).
    snapshot = ["evaluate", "--run", str(run), "--checkpoint", "step_000000032.pt",
                "--episodes", "1", "--record", "0", "--report", str(report)]
    assert main(snapshot) == 2
    assert main([*snapshot, "--overwrite"]) == 0
    data = json.loads(report.read_text())
    assert data["env_steps"] == 32 and data["checkpoint"] == "step_000000032.pt"


def test_reference_controllers_evaluate_on_the_push_benchmark(tmp_path):
    """`evaluate --run scripted` runs the straight-line pusher in the evaluation diagram; on the
    push benchmark's box it must reach the goal in some episodes (it does in ~3 of 4)."""
    report = tmp_path / "eval_scripted.json"
    assert main(["evaluate", "--run", "scripted", "--task", PUSH_TASK, "--episodes", "8",
                 "--record", "0", "--report", str(report)]) == 0
    data = json.loads(report.read_text())
    assert data["policy"] == "scripted" and len(data["episodes"]) == 8
    assert data["action_step"] == 0.03 and data["overrides"] == []  # the push task's 3 cm
    assert data["success_rate"] >= 0.25
    # Successful episodes end early (success terminates the episode) within 5 cm of the goal.
    for e in data["episodes"]:
        if e["success"]:
            assert e["steps"] < 100 and e["position_error"] <= 0.05
    # The zero-action reference leaves the box where it is: no success, full-length episodes.
    report = tmp_path / "eval_still.json"  # its own report: the scripted one is not its to replace
    assert main(["evaluate", "--run", "still", "--task", PUSH_TASK, "--episodes", "2",
                 "--record", "0", "--report", str(report)]) == 0
    data = json.loads(report.read_text())
    assert data["policy"] == "still" and data["success_rate"] == 0.0
    assert all(e["steps"] == 100 for e in data["episodes"])


def test_evaluate_refuses_to_sample_a_reference_controller(tmp_path, capsys):
    assert main(["evaluate", "--run", "scripted", "--stochastic", "--episodes", "1",
                 "--report", str(tmp_path / "r.json")]) == 2
    assert "--stochastic" in capsys.readouterr().err
    assert not (tmp_path / "r.json").exists()
