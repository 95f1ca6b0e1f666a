"""`corn-drake bench learner`: PPO update seconds per batch size, scaled to the smallest batch
of the same run (the paper-budget table of docs/many_core.md)."""

import json

import pytest
import torch

from corn_drake.cli import main


def test_report_times_every_batch_and_scales_to_the_smallest(tmp_path):
    path = tmp_path / "learner.json"
    threads = torch.get_num_threads()
    try:
        assert main(["bench", "learner", "--policy", "state", "--batches", "96,32",
                     "--report", str(path), "--torch-threads", "1"]) == 0
    finally:
        torch.set_num_threads(threads)  # the process's setting, for the tests after this one
    results = json.loads(path.read_text())["results"]
    rows = results["results"]
    # Whole rollouts of 2 envs x 16 steps: 32 and 96 transitions, smallest first.
    assert [r["batch"] for r in rows] == [32, 96]
    assert all(r["update_s"] > 0 for r in rows)
    assert rows[0]["per_transition_ratio"] == 1.0
    assert rows[1]["per_transition_ratio"] == pytest.approx(
        (rows[1]["update_s"] / 96) / (rows[0]["update_s"] / 32), rel=1e-9)
    assert results["torch_threads"] == 1 and results["epochs"] >= 1
