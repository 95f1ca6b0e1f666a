"""Runs on a real multi-node Ray cluster on this machine (issue 56): a local run stays local
beside a live cluster; on a cluster the workers spread over the nodes, reach a node that cannot
see the driver's files through Ray, and a node lost mid-run costs no update.

Every cluster here is started by the test (its own temp folder, one CPU per node) and ended by
it: only the processes it started."""

import contextlib
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np
import pytest
import torch

from corn_drake.config.training import TrainConfig
from corn_drake.rl.training.ppo_trainer import Trainer
from tests.fixtures import write_loadable_library
from tests.test_segment_workers import _WorkersInProcess
from tests.waiting import wait_until

ray = pytest.importorskip("ray")
psutil = pytest.importorskip("psutil")

pytestmark = pytest.mark.slow

RAY = str(Path(sys.executable).with_name("ray"))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _end_session(sid: int) -> None:
    """SIGKILL every process of session `sid` (what the test's `ray start` started: Ray keeps
    its processes in the session of the command that starts them), and wait for them."""
    procs = []
    for p in psutil.process_iter():
        with contextlib.suppress(psutil.Error, ProcessLookupError):
            if os.getsid(p.pid) == sid:
                procs.append(p)
    for p in procs:
        with contextlib.suppress(psutil.Error):
            p.kill()
    psutil.wait_procs(procs, timeout=30)


@pytest.fixture
def no_ray_in_this_process():
    if ray.is_initialized():
        ray.shutdown()
    yield
    if ray.is_initialized():
        ray.shutdown()


def _cfg(workers: int, rollout: int, updates: int, library: Path | None = None) -> TrainConfig:
    cfg = TrainConfig(policy="state", workers=workers, envs_per_worker=1, rollout_steps=rollout,
                      total_steps=updates * workers * rollout, checkpoint_every=1)
    cfg.env.task.episode_steps = 5
    if library is not None:
        obj = cfg.env.scene.object
        obj.kind, obj.library, obj.library_objects = "library", str(library), "train"
    return cfg


def test_a_local_run_starts_its_own_ray_beside_a_live_cluster(tmp_path, monkeypatch,
                                                             no_ray_in_this_process):
    # A live `ray start --head` cluster, named by RAY_ADDRESS as a shell that used it would
    # leave it: ray.init() without an address would join it (and refuse num_cpus).
    port = _free_port()
    temp = tempfile.mkdtemp(prefix="rc", dir="/tmp")  # short: Ray's socket paths live under it
    head = subprocess.Popen([RAY, "start", "--head", "--port", str(port), "--num-cpus", "1",
                             "--temp-dir", temp, "--include-dashboard", "false"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        assert head.wait(timeout=120) == 0
        monkeypatch.setenv("RAY_ADDRESS", f"127.0.0.1:{port}")
        metrics = Trainer(_cfg(1, rollout=4, updates=1), tmp_path / "run").train(progress=False)
        written = json.loads((tmp_path / "run" / "metrics.json").read_text())
        assert written["worker_nodes"] == metrics["worker_nodes"]
        assert not written["ray_cluster_joined"]
        assert not written["ray_gcs_address"].endswith(f":{port}")  # its own Ray, not the cluster's
        assert written["worker_nodes"] == [written["driver_node"]]
        ray.shutdown()
        # The cluster is still there and ran nothing of ours: its one CPU was never asked for.
        status = subprocess.run([RAY, "status", "--address", f"127.0.0.1:{port}"],
                                capture_output=True, text=True, timeout=120)
        assert status.returncode == 0 and "0.0/1.0 CPU" in status.stdout
    finally:
        _end_session(head.pid)
        import shutil

        shutil.rmtree(temp, ignore_errors=True)


@contextlib.contextmanager
def _cluster(cpus_a: int):
    """A head node with no CPU (the driver's: no worker can go there) and two worker nodes:
    node A with `cpus_a` CPUs, node B with 1. Node deaths are noticed within seconds."""
    from ray.cluster_utils import Cluster

    c = Cluster(initialize_head=True, head_node_args={
        "num_cpus": 0, "include_dashboard": False,
        "_system_config": {"health_check_period_ms": 500, "health_check_failure_threshold": 3,
                           "health_check_initial_delay_ms": 0}})
    try:
        nodes = {"A": c.add_node(num_cpus=cpus_a), "B": c.add_node(num_cpus=1)}
        c.wait_for_nodes()
        yield c, nodes
    finally:
        if ray.is_initialized():
            ray.shutdown()
        c.shutdown()


@pytest.fixture
def cluster(no_ray_in_this_process):
    """Node A has room for a replacement beside its own worker."""
    with _cluster(cpus_a=2) as c:
        yield c


def test_ppo_on_two_nodes_without_the_drivers_files_and_a_node_lost_mid_run(
        tmp_path, monkeypatch, capsys, cluster):
    from corn_drake.rl.workers import cluster as placement
    from corn_drake.rl.workers.ray_workers import init_ray

    c, nodes = cluster
    library = write_loadable_library(tmp_path / "lib", 2)
    rollout = 150  # a second or more of stepping: the node's loss lands inside it
    # The reference: the same two workers' collection computed in this process (bit for bit the
    # Ray path's; tests/test_segment_workers.py), one whole update, then the second segment.
    reference = _WorkersInProcess(_cfg(2, rollout, updates=1, library=library), tmp_path / "ref")
    reference.train(progress=False)
    expected = reference._collect()
    del reference

    # No node may read the driver's library: it is moved away right after the driver read it.
    hidden = tmp_path / "moved_away"
    pack = placement.pack_library

    def pack_then_move(factory):
        packed = pack(factory)
        library.rename(hidden)
        return packed

    monkeypatch.setattr(placement, "pack_library", pack_then_move)
    init_ray(c.address)
    trainer = Trainer(_cfg(2, rollout, updates=1, library=library), tmp_path / "run")
    metrics = trainer.train(progress=False)
    written = json.loads((tmp_path / "run" / "metrics.json").read_text())
    first_nodes = written["worker_nodes"]
    assert written["ray_cluster_joined"] and written["worker_restarts"] == []
    assert set(first_nodes) == {nodes["A"].node_id, nodes["B"].node_id}  # one on each
    assert metrics["global_step"] == 2 * rollout

    # Node B lost while its worker steps the second update's segment.
    victim = first_nodes.index(nodes["B"].node_id)
    pid = trainer.rollouts.worker_pids()[victim]
    capsys.readouterr()
    done = []
    collecting = threading.Thread(target=lambda: done.append(trainer._collect()))
    collecting.start()
    process = psutil.Process(pid)
    busy_from = sum(process.cpu_times()[:2])
    wait_until(lambda: sum(process.cpu_times()[:2]) > busy_from + 0.05,
               "the worker on node B to start stepping", poll_s=0.05)
    c.remove_node(nodes["B"], allow_graceful=False)
    collecting.join()
    assert trainer.rollouts.restarts == 1 and done
    # The update lost nothing: the other worker's columns are the reference's bit for bit, and
    # the replacement collected the victim's whole segment with the same weights and noise
    # (from its envs' first episodes, so the reference's columns for it differ).
    got, T = done[0], rollout
    keep = 1 - victim
    for key, value in got.stack.items():
        assert value.shape[:2] == (T, 2), key
        assert torch.isfinite(value).all(), key
        if key == "rewards":  # scaled by statistics of all the envs' rewards together
            continue
        torch.testing.assert_close(value[:, keep], expected.stack[key][:, keep], rtol=0, atol=0,
                                   msg=key)
    for key, value in got.obs.items():
        torch.testing.assert_close(value.reshape(T, 2, -1)[:, keep],
                                   expected.obs[key].reshape(T, 2, -1)[:, keep], rtol=0, atol=0,
                                   msg=key)
    lines = [line for line in capsys.readouterr().out.splitlines() if "died" in line]
    assert len(lines) == 1 and f"worker {victim} on node" in lines[0], lines
    print(lines[0], file=sys.stderr)  # what a user reads (shown with -s or on failure)
    # The run goes on with the replacement on node A, and metrics.json says what happened.
    trainer.cfg.total_steps += 2 * rollout
    trainer.train(progress=False)
    written = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert written["worker_nodes"] == [nodes["A"].node_id] * 2
    [death] = written["worker_restarts"]
    assert death["node"] == nodes["B"].node_id and death["worker"] == victim
    assert "node" in death["reason"] or "worker" in death["reason"], death


def test_a_lost_node_whose_workers_fit_nowhere_stops_the_run_with_its_checkpoint(
        tmp_path, no_ray_in_this_process):
    from corn_drake.rl.workers.cluster import NoRoomForWorkers
    from corn_drake.rl.workers.ray_workers import init_ray
    from corn_drake.storage.checkpoint_files import load_checkpoint

    with _cluster(cpus_a=1) as (c, nodes):
        init_ray(c.address)
        run = tmp_path / "run"
        trainer = Trainer(_cfg(2, rollout=4, updates=1), run)
        trainer.train(progress=False)
        saved = (run / "checkpoints" / "last.pt").read_bytes()
        c.remove_node(nodes["B"], allow_graceful=False)
        trainer.cfg.total_steps *= 2
        with pytest.raises(NoRoomForWorkers) as stopped:
            trainer.train(progress=False)
        message = str(stopped.value)
        assert "\n" not in message and "room for 1 worker" in message, message
        # The run's checkpoint is the one before the loss, whole: the run resumes from it.
        assert (run / "checkpoints" / "last.pt").read_bytes() == saved
        assert load_checkpoint(run / "checkpoints" / "last.pt")["update_index"] == 1


def _hide_after_packing(monkeypatch):
    """Every library the driver packs for its workers is moved away right after: no worker may
    open the driver's path."""
    from corn_drake.rl.workers import cluster as placement

    pack = placement.pack_library

    def pack_then_move(factory):
        packed = pack(factory)
        library = Path(factory.teacher_config.scene.object.library)
        library.rename(library.with_name(library.name + "_moved_away"))
        return packed

    monkeypatch.setattr(placement, "pack_library", pack_then_move)


def test_primitive_and_distill_workers_on_two_nodes_without_the_drivers_files(
        tmp_path, monkeypatch, no_ray_in_this_process):
    from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
    from corn_drake.config.primitive import PrimitiveTrainConfig
    from corn_drake.config.teacher import TeacherDiagramConfig
    from corn_drake.rl.envs.vec_env import EnvFactory
    from corn_drake.rl.training.primitive_trainer import PrimitiveTrainer
    from corn_drake.rl.workers.ray_workers import RayEnvBatch, init_ray
    from tests.test_primitive_workers import ENCODER, load_encoder

    _hide_after_packing(monkeypatch)
    with _cluster(cpus_a=1) as (c, nodes):
        init_ray(c.address)
        both = {nodes["A"].node_id, nodes["B"].node_id}
        # The contact-primitive policy's workers, one per node, on library objects.
        cfg = PrimitiveTrainConfig(env=load_primitive_env_config("push"), workers=2,
                                   envs_per_worker=1, total_steps=4, random_steps=0,
                                   learning_starts=2, log_every=2, checkpoint_every=2,
                                   hindsight_goals=0)
        obj = cfg.env.scene.object
        library = write_loadable_library(tmp_path / "lib_primitive", 2)
        obj.kind, obj.library, obj.library_objects = "library", str(library), "train"
        metrics = PrimitiveTrainer(cfg, tmp_path / "prim", load_encoder("corn", ENCODER)).train(
            progress=False)
        written = json.loads((tmp_path / "prim" / "metrics.json").read_text())
        assert metrics["global_step"] == 4
        assert set(written["worker_nodes"]) == both and written["worker_restarts"] == []
        # Distill's lock-step workers (RayEnvBatch), one per node.
        env = TeacherDiagramConfig()
        library = write_loadable_library(tmp_path / "lib_distill", 2)
        env.scene.object.kind, env.scene.object.library = "library", str(library)
        env.scene.object.library_objects = "train"
        batch = RayEnvBatch(EnvFactory(env, seed=0), num_workers=2, envs_per_worker=1)
        assert set(batch.record.nodes) == both
        obs = batch.reset()
        step = batch.step(np.zeros((2, 20)))
        assert step.rewards.shape == (2,) and obs["cloud"].shape[0] == 2
        assert batch.record.report()["worker_restarts"] == []


def test_a_node_in_its_own_mount_namespace_trains_without_the_library(tmp_path,
                                                                       no_ray_in_this_process):
    # As on a machine without a shared filesystem: node B's raylet (and so its workers) runs in
    # a mount namespace where a tmpfs hides the library's folder; the head has no CPU, so the
    # one worker must run there, on the files that came through Ray.
    from ray.cluster_utils import Cluster

    from corn_drake.rl.workers.ray_workers import init_ray

    if os.geteuid() != 0 or subprocess.run(["unshare", "-m", "true"]).returncode != 0:
        pytest.skip("needs root and unshare -m (a mount namespace)")
    library = write_loadable_library(tmp_path / "lib", 2)
    c = Cluster(initialize_head=True, head_node_args={"num_cpus": 0, "include_dashboard": False})
    node = None
    try:
        hide = (f"mount -t tmpfs tmpfs {library} && test ! -e {library}/manifest.json && "
                f"exec {RAY} start --address {c.address} --num-cpus 1")
        node = subprocess.Popen(["unshare", "-m", "--propagation", "private", "sh", "-c", hide],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                start_new_session=True)
        assert node.wait(timeout=120) == 0
        init_ray(c.address)
        run = tmp_path / "run"
        metrics = Trainer(_cfg(1, rollout=4, updates=1, library=library), run).train(
            progress=False)
        written = json.loads((run / "metrics.json").read_text())
        assert metrics["global_step"] == 4 and written["worker_restarts"] == []
        assert written["worker_nodes"][0] != written["driver_node"]
    finally:
        if ray.is_initialized():
            ray.shutdown()
        if node is not None:
            _end_session(node.pid)  # the node's raylet and workers: `ray start`'s session
        c.shutdown()


def test_bench_scale_on_a_two_node_cluster_names_both_nodes(tmp_path, no_ray_in_this_process):
    # `bench scale --ray-address`: each worker count's workers join the cluster (the head has no
    # CPU: none can run beside the driver), and the report names the nodes each row ran on.
    from corn_drake.cli import main

    with _cluster(cpus_a=1) as (c, nodes):
        report = tmp_path / "scale.json"
        assert main(["bench", "scale", "--report", str(report), "--ray-address", c.address,
                     "--workers", "2", "--policy", "state", "--envs-per-worker", "1",
                     "--rollout-steps", "4", "--updates", "1", "--warmup-updates", "0",
                     "--torch-threads", "1"]) == 0
        results = json.loads(report.read_text())["results"]
        both = sorted([nodes["A"].node_id, nodes["B"].node_id])
        assert results["workers"] == [1, 2] and results["nodes"] == [1, 2]
        assert results["worker_nodes"][1] == both and results["worker_nodes"][0][0] in both
        one, two = results["runs"]
        assert sorted(two["worker_nodes"]) == both and two["nodes"] == 2
        assert results["efficiency"][0] == 1.0 and all(r > 0 for r in results["steps_per_s"])
        assert results["ray_address"] == c.address and results["warnings"] == []
        assert results["driver_node"] not in both  # the learner stayed on the driver's node
        assert one["worker_restarts"] == two["worker_restarts"] == 0


def test_distill_command_on_a_two_node_cluster_without_the_drivers_files(
        tmp_path, monkeypatch, no_ray_in_this_process):
    # The whole `corn-drake distill` (DAgger student) with --ray-address: one lock-step worker
    # per node, student envs on a library the driver moved away after packing it, a shipped
    # teacher (models/weights/push_state) and the shipped CORN encoder.
    from corn_drake.cli import main
    from tests.paths import REPO_ROOT

    _hide_after_packing(monkeypatch)
    library = write_loadable_library(tmp_path / "lib", 2)
    weights = REPO_ROOT / "models" / "weights"
    with _cluster(cpus_a=1) as (c, nodes):
        out = tmp_path / "student"
        assert main(["distill", "--run", str(weights / "push_state"), "--encoder",
                     str(weights / "push_corn" / "encoder.pt"), "--objects", str(library),
                     "--perception", "ground_truth", "--workers", "2", "--envs-per-worker", "1",
                     "--steps", "8", "--window", "4", "--set", "task.episode_steps=5",
                     "--log-every", "1", "--checkpoint-every", "1", "--torch-threads", "1",
                     "--ray-address", c.address, "--out", str(out), "--no-progress"]) == 0
        written = json.loads((out / "metrics.json").read_text())
        assert written["global_step"] == 8 and written["ray_cluster_joined"]
        assert set(written["worker_nodes"]) == {nodes["A"].node_id, nodes["B"].node_id}
        assert written["worker_restarts"] == [] and written["driver_node"] not in \
            written["worker_nodes"]
