"""Pinning rollout workers to cores (rl/workers/core_pinning.py, `pin_workers`): which core worker w
gets, that a pinned process really runs on that core alone, and that every kind of Ray worker
(PPO segments, primitives, lock-step envs) is pinned when the run asks, a replaced one too."""

import multiprocessing
import os
import signal

import numpy as np
import psutil
import pytest

from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.config.training import TrainConfig
from corn_drake.rl.workers.core_pinning import pin_process, pin_worker, worker_core
from corn_drake.rl.envs.vec_env import EnvFactory

ray = pytest.importorskip("ray")


def test_worker_w_gets_core_w_plus_one_and_wraps_around():
    cpus = [3, 5, 7, 9]  # usable cores need not start at 0 or be contiguous
    assert [worker_core(w, cpus) for w in range(6)] == [5, 7, 9, 3, 5, 7]
    assert worker_core(4, [2]) == 2  # one core: everyone shares it
    assert worker_core(0, {9, 3}) == 9  # any iterable, in core order
    with pytest.raises(ValueError, match="worker index"):
        worker_core(-1, cpus)
    with pytest.raises(ValueError, match="no cores"):
        worker_core(0, [])


def test_a_core_this_process_may_not_use_is_refused_by_number():
    outside = max(os.sched_getaffinity(0)) + 1000
    with pytest.raises(ValueError, match=f"core {outside} "):
        pin_process(outside)
    before = os.sched_getaffinity(0)
    assert pin_worker(None) is None and os.sched_getaffinity(0) == before  # left as it was


def _pinned_affinity(index, results):
    results.put((pin_worker(index), sorted(os.sched_getaffinity(0))))


def test_a_pinned_process_runs_on_its_core_alone():
    ctx = multiprocessing.get_context("spawn")  # never pin the test process itself
    results = ctx.Queue()
    for index in (0, 1):
        child = ctx.Process(target=_pinned_affinity, args=(index, results))
        child.start()
        core, affinity = results.get(timeout=120)
        child.join()
        assert core == worker_core(index) and affinity == [core]


@pytest.fixture(scope="module")
def local_ray():
    from corn_drake.rl.workers.ray_workers import init_ray

    init_ray(num_cpus=2)
    yield
    ray.shutdown()


def _affinities(pids):
    return [psutil.Process(pid).cpu_affinity() for pid in pids]


def test_segment_workers_are_pinned_and_a_replacement_takes_the_dead_ones_core(tmp_path,
                                                                                local_ray):
    from corn_drake.rl.ppo.trainer import Trainer

    def cfg(pin):
        return TrainConfig(policy="state", workers=2, envs_per_worker=1, rollout_steps=2,
                           total_steps=4, pin_workers=pin)

    pinned = Trainer(cfg(True), tmp_path / "pinned")
    assert _affinities(pinned.rollouts.worker_pids()) == [[worker_core(0)], [worker_core(1)]]
    os.kill(pinned.rollouts.worker_pids()[1], signal.SIGKILL)
    pinned._collect()
    assert pinned.rollouts.restarts == 1
    assert _affinities(pinned.rollouts.worker_pids()) == [[worker_core(0)], [worker_core(1)]]
    unpinned = Trainer(cfg(False), tmp_path / "unpinned")
    everything = sorted(os.sched_getaffinity(0))
    assert _affinities(unpinned.rollouts.worker_pids()) == [everything, everything]


def test_primitive_and_lock_step_workers_are_pinned_when_asked(tmp_path, local_ray):
    from corn_drake.config.diagram_files import load_primitive_env_config
    from corn_drake.config.primitive import PrimitiveTrainConfig
    from corn_drake.rl.pretrained_encoders import load_encoder
    from corn_drake.package_data import data_dir
    from corn_drake.rl.primitive.trainer import PrimitiveTrainer
    from corn_drake.rl.workers.ray_workers import RayEnvBatch

    expected = [[worker_core(0)], [worker_core(1)]]
    cfg = PrimitiveTrainConfig(env=load_primitive_env_config("push"), workers=2,
                               envs_per_worker=1, total_steps=2, pin_workers=True)
    encoder = load_encoder("corn", data_dir("models") / "weights" / "push_corn" / "encoder.pt")
    trainer = PrimitiveTrainer(cfg, tmp_path, encoder)
    assert _affinities(trainer.workers.worker_pids()) == expected
    batch = RayEnvBatch(EnvFactory(TeacherDiagramConfig(), seed=0), num_workers=2,
                        envs_per_worker=1, pin=True)
    assert _affinities(batch.worker_pids()) == expected
    batch.reset()
    os.kill(batch.worker_pids()[0], signal.SIGKILL)
    batch.step(np.zeros((2, 20)))
    assert batch.restarts == 1 and _affinities(batch.worker_pids()) == expected


def test_pin_workers_is_recorded_and_may_change_on_a_resume(tmp_path, capsys):
    """Which cores the workers run on does not change what a run learns: `--pin-workers` on a
    resume is taken, not refused, and the run's config records it."""
    from corn_drake.cli import main
    from corn_drake.run_folders.config_file import load_run_config

    run = tmp_path / "run"
    common = ["train", "--policy", "state", "--envs-per-worker", "1", "--rollout-steps", "4",
              "--set", "task.episode_steps=5", "--no-progress", "--out", str(run)]
    assert main([*common, "--steps", "4"]) == 0
    assert load_run_config(run).pin_workers is False
    capsys.readouterr()
    assert main([*common, "--steps", "8", "--pin-workers"]) == 0
    assert "pin_workers" in capsys.readouterr().out
    assert load_run_config(run).pin_workers is True
