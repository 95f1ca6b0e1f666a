"""`evaluate` for watching (issue 36): it says where the recordings went, shows a progress bar
over the episodes unless --no-progress, and --keep-open holds Meshcat until Ctrl-C."""

import json
import os
import signal
import subprocess
import sys

from corn_drake.cli import main
from tests.paths import REPO_ROOT
from tests.waiting import wait_until

# The zero-action reference on the push task, two-step episodes: the cheapest real evaluation.
EVALUATE = ["evaluate", "--run", "still", "--task", "push", "--set", "task.episode_steps=2"]


def test_evaluate_prints_where_the_recordings_went_and_shows_progress(tmp_path, capsys):
    report = tmp_path / "eval.json"
    assert main([*EVALUATE, "--episodes", "2", "--record", "1", "--report", str(report)]) == 0
    out, err = capsys.readouterr()
    recordings = tmp_path / "eval_recordings"
    assert f"{recordings}/" in out and len(list(recordings.glob("*.html"))) == 1
    assert "episodes: 100%" in err and "2/2" in err  # the bar reached the end
    assert main([*EVALUATE, "--episodes", "1", "--record", "0", "--no-progress",
                 "--report", str(report), "--overwrite"]) == 0  # fewer episodes: afresh
    out, err = capsys.readouterr()
    assert "episodes:" not in err and "recordings" not in out  # none recorded, none named


def test_keep_open_holds_meshcat_until_ctrl_c(tmp_path):
    report = tmp_path / "eval.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT),
                                                         os.environ.get("PYTHONPATH", "")])}
    lines = tmp_path / "stdout.txt"
    with open(lines, "w") as stdout:
        proc = subprocess.Popen([sys.executable, "-m", "corn_drake.cli", *EVALUATE, "--episodes",
                                 "1", "--record", "0", "--no-progress", "--keep-open",
                                 "--report", str(report)], stdout=stdout,
                                stderr=subprocess.DEVNULL, env=env, cwd=tmp_path)
    try:
        wait_until(lambda: "press Ctrl-C" in lines.read_text() or proc.poll() is not None,
                   "evaluate --keep-open to finish its episodes")
        assert proc.poll() is None, lines.read_text()  # still holding Meshcat after the episodes
        text = lines.read_text()
        assert "Meshcat live view: http" in text and report.is_file()
        assert json.loads(report.read_text())["policy"] == "still"
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=600) == 0
        assert "closed Meshcat" in lines.read_text()
    finally:
        if proc.poll() is None:
            proc.kill()
