"""A SIGTERM that lands while Ray is starting ends the command in one line (exit 143), not in
Ray's native stack dump and exit 134 (issue 53): the signal is held until ray.init returns."""

import os
import signal
import subprocess
import sys

import pytest

from tests.waiting import wait_until

pytest.importorskip("ray")
psutil = pytest.importorskip("psutil")

TRAIN = ["train", "--policy", "state", "--steps", "1000000", "--envs-per-worker", "1",
         "--workers", "1", "--rollout-steps", "8", "--no-progress"]


def _ray_starting(proc: subprocess.Popen) -> bool:
    """Ray's first processes (its GCS server) are children of the command: ray.init is under
    way and has not returned (the workers are not up yet)."""
    try:
        children = psutil.Process(proc.pid).children(recursive=True)
        return any("gcs_server" in " ".join(c.cmdline()) for c in children)
    except psutil.Error:
        return False


def _is_ray(process) -> bool:
    """A Ray server process (a zombie or one gone meanwhile: ended, so not one)."""
    try:
        command = " ".join(process.cmdline())
    except psutil.Error:
        return False
    return "gcs_server" in command or "raylet" in command


@pytest.mark.slow
def test_a_sigterm_while_ray_starts_ends_in_one_line(tmp_path):
    run = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "corn_drake.cli", *TRAIN, "--out", str(run)],
                            env={**os.environ, "PYTHONUNBUFFERED": "1"}, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    wait_until(lambda: _ray_starting(proc) or proc.poll() is not None, "Ray to start starting",
               poll_s=0.02)
    os.kill(proc.pid, signal.SIGTERM)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signal.SIGTERM, stderr
    assert "Traceback" not in stderr and "*** SIGTERM" not in stderr, stderr
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert lines[-1].startswith("corn-drake train: interrupted (SIGTERM)"), stderr
    # Ray's processes went with it: none is left a child of this test.
    leftovers = [p for p in psutil.Process().children(recursive=True) if _is_ray(p)]
    psutil.wait_procs(leftovers, timeout=30)
    assert not [p for p in leftovers if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]


@pytest.mark.slow
def test_a_sigterm_to_the_whole_process_group_ends_a_ray_run_in_one_line(tmp_path):
    """As GNU timeout or SLURM send it: the group, Ray's processes included were they in it."""
    run = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "corn_drake.cli", *TRAIN,
                             "--set", "checkpoint_every=1", "--out", str(run)],
                            env={**os.environ, "PYTHONUNBUFFERED": "1"}, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    checkpoint = run / "checkpoints" / "last.pt"
    wait_until(lambda: checkpoint.exists() or proc.poll() is not None, "the first checkpoint",
               poll_s=0.2)
    assert checkpoint.exists(), proc.communicate()[1]
    os.killpg(proc.pid, signal.SIGTERM)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signal.SIGTERM, stderr
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert "Traceback" not in stderr and lines[-1].startswith(
        "corn-drake train: interrupted (SIGTERM)"), stderr
