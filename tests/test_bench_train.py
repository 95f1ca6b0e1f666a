"""`corn-drake bench train`: the report's figures and time breakdown, and the phase timer."""

import json
import math

import pytest
import torch

from corn_drake import DIAGRAMS_DIR
from corn_drake.bench.phases import PhaseTimer
from corn_drake.bench.training.train import FRACTION_KEYS
from corn_drake.cli import main

ENVS, UPDATES, ROLLOUT = 2, 1, 4


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """One small run on the push task with 3-step episodes, so that episodes end (and envs
    reset) inside the timed update: one warm-up update (steps 1-4) and one timed (5-8)."""
    root = tmp_path_factory.mktemp("bench_train")
    push = (DIAGRAMS_DIR / "tasks" / "push.yaml").read_text()
    assert "episode_steps: 100" in push
    task = root / "push_short.yaml"
    task.write_text(push.replace("episode_steps: 100", "episode_steps: 3"))
    path = root / "train.json"
    threads = torch.get_num_threads()
    try:
        assert main(["bench", "train", "--report", str(path), "--task", str(task),
                     "--envs-per-worker", str(ENVS), "--updates", str(UPDATES), "--rollout-steps",
                     str(ROLLOUT), "--bare-steps", "12", "--torch-threads", "1"]) == 0
    finally:
        torch.set_num_threads(threads)  # the process's setting, for the tests after this one
    return json.loads(path.read_text())


def test_report_has_the_rates_and_their_ratio(report):
    results = report["results"]
    train, bare = results["train_steps_per_s"], results["bare_physics_policy_steps_per_s"]
    assert train > 0 and bare > 0
    assert math.isclose(results["train_ratio"], train / bare, rel_tol=1e-12)
    assert results["steps"] == ENVS * UPDATES * ROLLOUT
    assert math.isclose(results["time_s"]["total"] * train, results["steps"], rel_tol=1e-9)
    # The trainer's own timer covers the same interval (plus the normaliser update). Within a
    # factor of 3, not a close tolerance: load from other processes can stretch the part only one
    # timer covers; a rate from the wrong interval or step count is off by far more.
    assert train / 3 < results["trainer_logged_steps_per_s"] < 3 * train
    assert results["task"] == "push" and results["policy"] == "corn"
    assert report["machine"]["cpu_count"] >= 1 and results["torch_threads"] == 1


def test_time_fractions_add_up_and_reach_every_phase(report):
    results = report["results"]
    fractions = results["time_fractions"]
    assert set(fractions) == set(FRACTION_KEYS)
    assert all(value >= 0 for value in fractions.values()), fractions
    assert abs(sum(fractions.values()) - 1.0) < 1e-6
    # Every timer was reached: the envs stepped, the policy acted, PPO updated, episodes ended.
    assert results["episodes_finished"] >= ENVS
    for key in ("physics", "python_systems", "policy_inference", "ppo_update", "object_switching"):
        assert fractions[key] > 0, key
    # Physics is the bare plant's time for the steps trained, within the time spent stepping.
    seconds = results["time_s"]
    assert seconds["physics"] <= seconds["advance_to"]
    assert math.isclose(fractions["physics"], min(results["train_ratio"],
                                                  seconds["advance_to"] / seconds["total"]),
                        rel_tol=1e-9)


def test_phase_timer_counts_exclusive_time_inside_windows_only():
    now = [0.0]
    timer = PhaseTimer(clock=lambda: now[0])

    def tick(dt):
        now[0] += dt

    with timer.phase("outside"):  # no window open: not counted
        tick(5)
    timer.open_window()
    tick(1)
    with timer.phase("a"):
        tick(2)
        with timer.phase("b"):
            tick(3)
        tick(4)
    with timer.phase("b"):
        tick(0.5)
    timer.close_window()
    assert timer.seconds["a"] == 6 and timer.seconds["b"] == 3.5
    assert timer.seconds[PhaseTimer.WINDOW] == 1 and timer.window_seconds == 10.5
    assert "outside" not in timer.seconds and timer.calls["b"] == 2
    with pytest.raises(RuntimeError):
        timer.close_window()


def test_wrapped_method_is_timed_on_that_instance_only():
    now = [0.0]
    timer = PhaseTimer(clock=lambda: now[0])

    class Thing:
        def work(self, dt):
            now[0] += dt
            return dt * 2

    timed, plain = Thing(), Thing()
    timer.wrap(timed, "work", "work")
    timer.open_window()
    assert timed.work(2) == 4 and plain.work(3) == 6
    timer.close_window()
    assert timer.seconds["work"] == 2 and timer.calls["work"] == 1
    assert timer.seconds[PhaseTimer.WINDOW] == 3
