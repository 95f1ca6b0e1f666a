"""A replacement worker is waited for with the room checked again (rl/workers/cluster.py).

The race a CI run met on a real two-node cluster (tests/test_ray_cluster.py): a worker's death
reached the driver 0.25 s before Ray marked its node dead, the first room check still counted
the lost node's CPU, and the replacement, fitting nowhere, was waited for forever (72 minutes,
until CI's limit). Here the first check is made to see that stale room (hosting_slots patched
for one call) on a real local Ray of one CPU; every later check sees Ray's own nodes."""

import pytest

ray = pytest.importorskip("ray")

from corn_drake.rl.workers import cluster  # noqa: E402
from corn_drake.rl.workers.cluster import NoRoomForWorkers, WorkerBase, WorkerRecord  # noqa: E402
from corn_drake.rl.workers.ray_workers import init_ray  # noqa: E402


@pytest.fixture(scope="module")
def one_cpu_ray():
    if ray.is_initialized():
        ray.shutdown()
    init_ray(num_cpus=1)
    yield
    ray.shutdown()


def _worker(cpus: float):
    return ray.remote(WorkerBase).options(num_cpus=cpus).remote()


def test_a_replacement_that_fits_nowhere_stops_with_no_room_even_if_the_first_check_saw_room(
        one_cpu_ray, monkeypatch):
    holding = _worker(1.0)  # the surviving worker: the only CPU
    ray.get(holding.node.remote())
    lost = _worker(1.0)  # pending: stands for the worker whose node is gone
    real = cluster.hosting_slots
    calls = []

    def stale_then_real(cpus):
        calls.append(cpus)
        return 2 if len(calls) == 1 else real(cpus)  # the lost node still counted, once

    monkeypatch.setattr(cluster, "hosting_slots", stale_then_real)
    monkeypatch.setattr(cluster, "ROOM_RECHECK_S", 0.2)
    workers = [holding, lost]
    spawned = []

    def spawn():
        spawned.append(_worker(1.0))
        return spawned[-1]

    with pytest.raises(NoRoomForWorkers) as stopped:
        cluster.spawn_replacement("rollout", workers, 1, 1.0, spawn)
    assert "replacing rollout worker 1" in str(stopped.value)
    assert "room for 1 worker" in str(stopped.value), stopped.value
    assert len(spawned) == 1 and len(calls) >= 2
    # The pending replacement was killed: it will not start when room comes back.
    with pytest.raises(ray.exceptions.RayActorError):
        ray.get(spawned[0].node.remote(), timeout=120)  # a bound on a hang, not a speed
    ray.kill(holding)


def test_a_replacement_with_room_is_waited_for_and_recorded(one_cpu_ray):
    workers = [_worker(0.5), _worker(0.5)]
    ray.get([w.node.remote() for w in workers])
    record = WorkerRecord("rollout")
    record.nodes = ray.get([w.node.remote() for w in workers])
    old = workers[1]
    cluster.spawn_replacement("rollout", workers, 1, 0.5, lambda: _worker(0.5))
    assert workers[1] is not old
    record.replaced(1, RuntimeError("its node died"), workers[1], "in a test")
    [death] = record.deaths
    assert death["worker"] == 1 and death["replacement_node"] == record.nodes[1]
    assert death["replacement_node"] == ray.get_runtime_context().get_node_id()
    for w in workers:
        ray.kill(w)


def _pool_worker(tmp_path):
    """A job worker whose first "die" job ends its process (as a lost node's would)."""
    import os

    marker = tmp_path / "died_once"

    class JobWorker(WorkerBase):
        def do(self, job):
            if job == "die" and not marker.exists():
                marker.write_text("x")
                os._exit(1)
            return job

    return ray.remote(JobWorker)


def test_a_job_pool_with_no_room_for_a_replacement_goes_on_with_the_others(
        one_cpu_ray, monkeypatch, capsys, tmp_path):
    from corn_drake.rl.workers.job_pool import run_on_pool

    Worker = _pool_worker(tmp_path)
    monkeypatch.setattr(cluster, "hosting_slots", lambda cpus: 1)  # the dead one's node is gone
    done = []
    run_on_pool(lambda: Worker.options(num_cpus=0.5).remote(), 2, 0.5,
                ["die", "a", "b", "c"], lambda w, job: w.do.remote(job),
                lambda job, result: done.append(result), "test", lambda job: f"job {job}")
    assert sorted(done) == ["a", "b", "c", "die"]  # every job once, "die" played again
    lines = [line for line in capsys.readouterr().out.splitlines() if "test worker" in line]
    assert len(lines) == 1 and "no room for a replacement, job die goes to the other 1" in lines[0]


def test_a_job_pool_whose_last_worker_dies_with_no_room_says_so(one_cpu_ray, monkeypatch,
                                                                 tmp_path):
    from corn_drake.rl.workers.job_pool import run_on_pool

    Worker = _pool_worker(tmp_path)
    monkeypatch.setattr(cluster, "hosting_slots", lambda cpus: 0)
    with pytest.raises(NoRoomForWorkers, match="replacing test worker 0"):
        run_on_pool(lambda: Worker.options(num_cpus=0.5).remote(), 1, 0.5, ["die", "a"],
                    lambda w, job: w.do.remote(job), lambda job, result: None, "test",
                    lambda job: f"job {job}")


def test_workers_still_pending_when_a_node_is_lost_stop_with_no_room(one_cpu_ray, monkeypatch):
    """A pool's first placement (WorkerRecord.placed) re-checks the room while a worker is
    pending: the room its start counted is gone (one CPU for two workers of one)."""
    monkeypatch.setattr(cluster, "ROOM_RECHECK_S", 0.2)
    workers = [_worker(1.0), _worker(1.0)]  # the second cannot start beside the first
    with pytest.raises(NoRoomForWorkers, match="rollout workers: .* room for 1 worker"):
        WorkerRecord("rollout").placed(workers, 1.0)
    for w in workers:
        ray.kill(w)
