"""What an evaluate report says it measured (issues 33 and 35): each episode's failure category
and the counts, whether the report is complete, the checkpoint file actually used, the object
library and its manifest's hash; an interrupted evaluate keeps the finished episodes."""

import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys

import pytest

from corn_drake.cli import main
from corn_drake.evaluation.failures import FAILURES
from tests.paths import REPO_ROOT
from tests.waiting import wait_until

STILL = ["evaluate", "--run", "still", "--task", "push", "--set", "task.episode_steps=2",
         "--record", "0", "--no-progress"]


def test_a_report_gives_each_episodes_failure_and_the_counts(tmp_path):
    report_path = tmp_path / "eval.json"
    assert main([*STILL, "--episodes", "3", "--report", str(report_path)]) == 0
    report = json.loads(report_path.read_text())
    assert report["complete"] is True and report["episodes_requested"] == 3
    # A zero action never reaches the object: every episode is "never_touched".
    assert [e["failure"] for e in report["episodes"]] == ["never_touched"] * 3
    assert report["failure_counts"] == {name: (3 if name == "never_touched" else 0)
                                        for name in FAILURES}
    motion = report["episodes"][0]["motion"]
    assert motion["moved"] < 0.01 and motion["start_position_error"] > 0.05
    # The untouched object ends still; no success, so none ending still.
    speed = report["episodes"][0]["end_speed"]
    assert 0 <= speed["linear"] < 0.02 and 0 <= speed["angular"] < 0.2
    assert report["successes_ending_still"] == 0


def test_a_report_names_its_library_and_the_checkpoint_it_used(tmp_path, capsys):
    from tests.fixtures import write_loadable_library

    library = write_loadable_library(tmp_path / "lib", num_train=1, num_unseen=1)
    run = tmp_path / "run"
    shutil.copytree(REPO_ROOT / "models" / "weights" / "push_state", run)
    checkpoints = run / "checkpoints"
    # An unusable last.pt: the run's previous checkpoint is evaluated, and the report says so.
    shutil.copy(checkpoints / "last.pt", checkpoints / "prev.pt")
    (checkpoints / "last.pt").write_bytes(b"damaged")
    report_path = tmp_path / "eval.json"
    assert main(["evaluate", "--run", str(run), "--objects", str(library), "--split", "unseen",
                 "--episodes", "1", "--record", "0", "--no-progress", "--set",
                 "task.episode_steps=2", "--report", str(report_path)]) == 0
    report = json.loads(report_path.read_text())
    assert report["checkpoint"] == "prev.pt"
    err = capsys.readouterr().err.splitlines()
    fallback = [line for line in err if line.startswith("warning: checkpoint unusable")]
    assert len(fallback) == 1 and fallback[0].endswith(f"{checkpoints / 'prev.pt'}")
    # A shipped folder evaluated on another library than its card's says so too.
    assert any(line.startswith("warning: object library") for line in err)
    digest = hashlib.sha256((library / "manifest.json").read_bytes()).hexdigest()
    assert report["library"] == {"path": str(library), "manifest_sha256": digest}


@pytest.mark.slow
def test_an_interrupted_evaluate_writes_the_finished_episodes_as_a_partial_report(tmp_path):
    report_path = tmp_path / "eval.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT),
                                                         os.environ.get("PYTHONPATH", "")])}
    err_path = tmp_path / "stderr.txt"
    argv = [a for a in STILL if a != "--no-progress"]  # the bar says how many episodes are done
    with open(err_path, "w") as err:
        proc = subprocess.Popen([sys.executable, "-m", "corn_drake.cli", *argv, "--episodes",
                                 "100000", "--record", "1", "--report", str(report_path)],
                                stdout=subprocess.DEVNULL, stderr=err, env=env)

    def finished() -> int:
        counts = re.findall(r"\| (\d+)/100000", err_path.read_text())
        return int(counts[-1]) if counts else 0

    try:
        wait_until(lambda: finished() >= 2 or proc.poll() is not None, "two finished episodes")
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=600) == 130
    finally:
        if proc.poll() is None:
            proc.kill()
    text = err_path.read_text()
    assert "Traceback" not in text and "interrupted (SIGINT)" in text
    report = json.loads(report_path.read_text())
    assert report["complete"] is False and report["episodes_requested"] == 100000
    assert len(report["episodes"]) >= 2 and sum(report["failure_counts"].values()) == \
        len(report["episodes"])
    # Only whole episodes' recordings: the first episode's, none of an unfinished one.
    assert len(list((tmp_path / "eval_recordings").glob("*.html"))) == 1
    # The report's lock goes with the interrupted evaluate (storage/file_locks.py).
    assert not (tmp_path / ".eval.json.lock").exists()
