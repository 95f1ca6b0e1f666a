"""`corn-drake bench cores`: N plain processes each collecting a segment worker's segments:
the report's figures recomputed from the seconds it records, and a process that dies reported
instead of waited for. (Bad flags
are rows of tests/test_cli_bad_input.py.)"""

import json
import multiprocessing
import os

import numpy as np
import pytest

from corn_drake.bench.training import cores
from corn_drake.cli import main

ENVS, STEPS, SEGMENTS = 1, 4, 2


def test_report_figures_follow_from_the_recorded_seconds(tmp_path):
    path = tmp_path / "cores.json"
    assert main(["bench", "cores", "--report", str(path), "--procs", "2",
                 "--envs-per-worker", str(ENVS), "--rollout-steps", str(STEPS),
                 "--segments", str(SEGMENTS), "--warmup-segments", "0"]) == 0
    results = json.loads(path.read_text())["results"]
    assert results["procs"] == [1, 2]  # the 1-process baseline added
    assert list(results["modes"]) == ["unpinned"]  # the earlier reports' shape
    for mode in results["modes"].values():
        runs = mode["runs"]
        assert [r["procs"] for r in runs] == [1, 2]
        base_pace = None
        for run in runs:
            seconds = np.asarray(run["seconds"])
            assert seconds.shape == (run["procs"], SEGMENTS) and (seconds > 0).all()
            paces = (ENVS * STEPS / seconds).mean(axis=1)
            base_pace = paces.mean() if base_pace is None else base_pace
            assert run["pace_mean"] == pytest.approx(paces.mean())
            assert run["pace_slowest"] == pytest.approx(paces.min())
            assert run["pace_ratio"] == pytest.approx(paces.mean() / base_pace)
            lockstep = np.mean(ENVS * STEPS / seconds.max(axis=0) / base_pace)
            assert run["lockstep_efficiency"] == pytest.approx(lockstep)
            assert run["lockstep_efficiency"] <= run["pace_ratio"] + 1e-9  # never above the mean
        assert mode["pace_ratio"][0] == 1.0
        assert mode["lockstep_efficiency"][0] == pytest.approx(1.0)  # 1 process: its own mean


def test_summary_of_known_seconds():
    run = {"procs": 2, "seconds": [[1.0, 2.0], [2.0, 2.0]]}  # 10 steps a segment
    summary = cores.summarise(run, 10, baseline_pace=10.0)
    assert summary["pace_per_process"] == pytest.approx([7.5, 5.0])
    assert summary["pace_mean"] == pytest.approx(6.25) and summary["pace_slowest"] == 5.0
    assert summary["pace_ratio"] == pytest.approx(0.625)
    # Both segments wait for a 2 s process: 5 steps/s against 10.
    assert summary["lockstep_efficiency"] == pytest.approx(0.5)


def test_a_process_that_dies_without_a_row_is_reported():
    ctx = multiprocessing.get_context("spawn")
    dead = ctx.Process(target=os._exit, args=(3,))
    dead.start()
    dead.join()
    with pytest.raises(RuntimeError, match=r"process 0 of 1 died \(exit code 3\)"):
        cores._gather(ctx.Queue(), [dead])
