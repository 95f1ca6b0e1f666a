"""The command line: subcommand discovery and the sim benchmark's report."""

import json
from pathlib import Path

from corn_drake.cli import build_parser, main


def test_subcommands_are_discovered():
    text = build_parser().format_help()
    assert "bench" in text and "demo" in text


def test_bench_sim_writes_report_with_baseline(tmp_path):
    report = tmp_path / "sim.json"
    assert main(["bench", "sim", "--report", str(report), "--steps", "30"]) == 0
    data = json.loads(report.read_text())
    results = data["results"]
    for key in ("policy_steps_per_s", "bare_physics_policy_steps_per_s", "overhead_ratio"):
        assert results[key] > 0
    assert abs(results["overhead_ratio"] - results["bare_physics_policy_steps_per_s"]
               / results["policy_steps_per_s"]) < 1e-9
    assert "cpu_count" in data["machine"]


def test_train_then_evaluate_writes_the_report_keys(tmp_path):
    run = tmp_path / "run"
    assert main(["train", "--policy", "state", "--steps", "64", "--envs-per-worker", "2",
                 "--rollout-steps", "16", "--episode-steps", "10", "--out", str(run),
                 "--no-progress"]) == 0
    report = tmp_path / "eval_state.json"
    assert main(["evaluate", "--run", str(run), "--episodes", "2", "--record", "1",
                 "--report", str(report)]) == 0
    data = json.loads(report.read_text())
    for key in ("success_rate", "balanced_success_rate", "per_object", "episodes"):
        assert key in data
    assert len(data["episodes"]) == 2 and 0.0 <= data["success_rate"] <= 1.0
    html = data["episodes"][0]["recording"]
    assert html and Path(html).stat().st_size > 10_000


def test_reference_controllers_evaluate_on_the_push_benchmark(tmp_path):
    """`evaluate --run scripted` runs the straight-line pusher in the evaluation diagram; on the
    push benchmark's box it must reach the goal in some episodes (it does in ~3 of 4)."""
    from corn_drake import DIAGRAMS_DIR

    report = tmp_path / "eval_scripted.json"
    assert main(["evaluate", "--run", "scripted", "--config",
                 str(DIAGRAMS_DIR / "reduced_benchmark_push.yaml"), "--episodes", "8",
                 "--record", "0", "--report", str(report)]) == 0
    data = json.loads(report.read_text())
    assert data["policy"] == "scripted" and len(data["episodes"]) == 8
    assert data["success_rate"] >= 0.25
    # Successful episodes end early (success terminates the episode) within 5 cm of the goal.
    for e in data["episodes"]:
        if e["success"]:
            assert e["steps"] < 100 and e["position_error"] <= 0.05
    # The zero-action reference leaves the box where it is: no success, full-length episodes.
    assert main(["evaluate", "--run", "still", "--config",
                 str(DIAGRAMS_DIR / "reduced_benchmark_push.yaml"), "--episodes", "2",
                 "--record", "0", "--report", str(report)]) == 0
    data = json.loads(report.read_text())
    assert data["policy"] == "still" and data["success_rate"] == 0.0
    assert all(e["steps"] == 100 for e in data["episodes"])


def test_train_ppo_overrides_change_fields_and_name_bad_input():
    import pytest

    from corn_drake.commands.train import ppo_overrides
    from corn_drake.config import PPOConfig

    ppo = ppo_overrides(PPOConfig(), ["lr=1e-4", "epochs=4", "kl_stop_factor=1e9"])
    assert (ppo.lr, ppo.epochs, ppo.kl_stop_factor) == (1e-4, 4, 1e9)
    assert ppo.clip == PPOConfig().clip  # untouched fields keep the paper's values
    with pytest.raises(ValueError, match="lrr"):
        ppo_overrides(PPOConfig(), ["lrr=1"])
    with pytest.raises(ValueError, match="not a int"):
        ppo_overrides(PPOConfig(), ["epochs=1.5"])


def test_evaluate_refuses_to_sample_a_reference_controller(tmp_path, capsys):
    assert main(["evaluate", "--run", "scripted", "--stochastic", "--episodes", "1",
                 "--report", str(tmp_path / "r.json")]) == 2
    assert "--stochastic" in capsys.readouterr().err
    assert not (tmp_path / "r.json").exists()
