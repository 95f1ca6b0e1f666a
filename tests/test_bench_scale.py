"""`corn-drake bench scale` (steps/s and efficiency per Ray worker count) and the learner's
`--device`: refused where the machine lacks it, checkpoints on the CPU, a run resumes anywhere.
(Bad --workers / --envs-per-worker / --device values are rows of tests/test_cli_bad_input.py.)"""

import collections
import json
import math

import numpy as np
import pytest
import torch

from corn_drake.bench.training import scale
from corn_drake.cli import main
from corn_drake.config.training import TrainConfig
from corn_drake.errors import InputError
from corn_drake.rl.training.ppo_trainer import Trainer, to_cpu
from tests.waiting import wait_until

WORKERS, ENVS_PER_WORKER, ROLLOUT, UPDATES = [1, 2], 1, 4, 1
NO_CUDA = pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has CUDA")


def _new_processes(before: set[int]) -> list:
    import psutil

    alive = []
    for p in psutil.Process().children(recursive=True):
        try:
            if p.pid not in before and p.status() != psutil.STATUS_ZOMBIE:
                alive.append(p)
        except psutil.Error:
            continue
    return alive


@pytest.mark.slow
def test_scale_report_with_real_ray_workers_and_no_process_left(tmp_path):
    psutil = pytest.importorskip("psutil")
    before = {p.pid for p in psutil.Process().children(recursive=True)}
    path = tmp_path / "scale.json"
    threads = torch.get_num_threads()
    assert main(["bench", "scale", "--report", str(path), "--workers", "1,2",
                 "--envs-per-worker", str(ENVS_PER_WORKER), "--rollout-steps", str(ROLLOUT),
                 "--updates", str(UPDATES), "--warmup-updates", "1", "--torch-threads", "1"]) == 0
    assert torch.get_num_threads() == threads  # the process's setting is given back
    report = json.loads(path.read_text())
    results = report["results"]
    assert results["workers"] == WORKERS and len(results["efficiency"]) == len(WORKERS)
    assert results["efficiency"][0] == 1.0 and not results["baseline_added"]
    rates = results["steps_per_s"]
    assert all(r > 0 for r in rates)
    assert math.isclose(results["efficiency"][1], rates[1] / 2 / rates[0], rel_tol=1e-12)
    for workers, run in zip(WORKERS, results["runs"]):
        assert run["workers"] == workers and run["steps"] == workers * ENVS_PER_WORKER * ROLLOUT
        assert math.isclose(run["time_s"]["total"] * run["steps_per_s"], run["steps"],
                            rel_tol=1e-9)
        fractions = run["time_fractions"]
        assert set(fractions) == set(scale.FRACTION_KEYS)
        assert all(v > 0 for v in fractions.values()), fractions  # every timer was reached
        assert abs(sum(fractions.values()) - 1) < 1e-9
        assert math.isclose(run["learner_share"], 1 - fractions["rollout_wait"], rel_tol=1e-9)
        # The workers' own pace: their envs x steps over their own collect() seconds, which
        # lie inside the learner's wait for them.
        assert 0 < run["worker_inference_share"] < 1
        # The slowest worker's own collection lies inside the learner's wait for it.
        assert 0 < run["slowest_collection_s_per_update"] <= run["rollout_wait_s_per_update"]
        assert run["env_steps_per_s_per_worker"] >= ENVS_PER_WORKER * ROLLOUT * UPDATES / \
            run["time_s"]["rollout_wait"] * (1 - 1e-9)
        # The trainer's own per-update timer covers the same interval (plus the normaliser).
        # Within a factor of 3, not a close tolerance: the part only one timer covers can be
        # stretched by load from other processes; a rate from the wrong interval or the wrong
        # step count is off by far more.
        assert run["steps_per_s"] / 3 < run["trainer_logged_steps_per_s"] < 3 * run["steps_per_s"]
        assert run["worker_restarts"] == 0
    local = results["in_process_run"]
    assert local["workers"] == 0 and local["worker_restarts"] == 0
    assert results["in_process_env_steps_per_s"] == local["env_steps_per_s_per_worker"] > 0
    assert results["ray_1_worker_vs_in_process"] == rates[0] / local["steps_per_s"]
    assert results["worker_pace_ratio"] == [r["env_steps_per_s_per_worker"] /
                                            results["in_process_env_steps_per_s"]
                                            for r in results["runs"]]
    assert results["device"] == "cpu" and results["torch_threads"] == 1
    assert results["usable_cpus"] >= 1 and report["machine"]["cpu_count"] >= 1
    # Each run shut its Ray down: nothing it started is left (the reaper ends Ray's agents).
    # They end on their own: wait for that however slow a busy machine is (the cap only
    # guards against a hang: a process still there then outlived its run).
    wait_until(lambda: not _new_processes(before), "the benchmark's Ray processes to end",
               poll_s=0.5)


def test_worker_counts_are_sorted_with_the_baseline_added(tmp_path, monkeypatch):
    """The report's assembly, on made-up rates (no Ray): 1 is measured first even when not
    asked for, and efficiency is each count's rate per worker over the 1-worker rate."""
    rates = {0: 110.0, 1: 100.0, 2: 180.0, 4: 300.0}  # 0: the envs in this process
    paces = {0: 100.0, 1: 85.0, 2: 80.0, 4: 70.0}  # each collector's env steps/s while stepping
    measured = []

    def fake_measure(args, env_cfg, workers):
        measured.append(workers)
        return {"workers": workers, "steps_per_s": rates[workers], "learner_share": 0.1 * workers,
                "env_steps_per_s_per_worker": paces[workers]}

    monkeypatch.setattr(scale, "measure", fake_measure)
    path = tmp_path / "scale.json"
    assert main(["bench", "scale", "--report", str(path), "--workers", "4,2"]) == 0
    results = json.loads(path.read_text())["results"]
    assert measured == [0, 1, 2, 4] and results["workers"] == [1, 2, 4]
    assert results["efficiency"] == [1.0, 0.9, 0.75]
    assert results["steps_per_s"] == [100.0, 180.0, 300.0]
    assert results["baseline_added"] and results["requested_workers"] == [4, 2]
    assert [r["efficiency"] for r in results["runs"]] == results["efficiency"]
    # Each worker's pace against the in-process pace of the same envs, in worker-count order.
    assert results["worker_pace_ratio"] == [0.85, 0.8, 0.7]
    assert results["in_process_env_steps_per_s"] == 100.0
    assert results["ray_1_worker_vs_in_process"] == 100.0 / 110.0


def test_oversubscribed_counts_are_warned_about():
    lines = scale.oversubscription_warnings([1, 2, 4, 8, 15], usable_cpus=8)
    assert [line.split(":")[0] for line in lines] == ["--workers 8", "--workers 15"]
    assert scale.oversubscription_warnings([1, 2, 4, 8, 15], usable_cpus=16) == []


@NO_CUDA
@pytest.mark.parametrize("argv", [
    ["train", "--policy", "state", "--device", "cuda", "--out", "{tmp}/run"],
    ["bench", "scale", "--report", "{tmp}/scale.json", "--device", "cuda"],
])
def test_cuda_on_a_machine_without_it_is_refused_before_any_work(tmp_path, capsys, argv):
    argv = [a.format(tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert "--device cuda" in err and "CUDA is not available" in err, err
    assert not (tmp_path / "run" / "config.yaml").exists() and not (tmp_path / "scale.json").exists()


@NO_CUDA
def test_trainer_refuses_a_config_asking_for_cuda(tmp_path):
    with pytest.raises(InputError, match="device cuda: CUDA is not available"):
        Trainer(TrainConfig(device="cuda"), tmp_path)
    assert not (tmp_path / "checkpoints").exists()


def test_to_cpu_keeps_structure_and_the_state_dict_version_record():
    state = torch.nn.Linear(2, 3).state_dict()
    moved = to_cpu({"agent": state, "rows": [torch.ones(2), 3], "pair": (torch.zeros(1), "x")})
    assert isinstance(moved["agent"], collections.OrderedDict)
    assert moved["agent"]._metadata == state._metadata  # load_state_dict reads module versions
    assert torch.equal(moved["agent"]["weight"], state["weight"])
    assert isinstance(moved["pair"], tuple) and moved["pair"][1] == "x" and moved["rows"][1] == 3


DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def _tensors(node):
    if isinstance(node, torch.Tensor):
        yield node
    elif isinstance(node, dict):
        for v in node.values():
            yield from _tensors(v)
    elif isinstance(node, (list, tuple)):
        for v in node:
            yield from _tensors(v)


@pytest.mark.parametrize("device", DEVICES)
def test_a_run_resumes_on_another_device_with_the_same_policy(tmp_path, capsys, device):
    """Trained on `device`: the checkpoint holds CPU tensors only, `device` is recorded and may
    change on a resume, and the run's agent rebuilt on the device acts exactly as the saved
    agent loaded on the CPU."""
    from corn_drake.contract import ACTION_DIM, observation_shapes
    from corn_drake.rl.ppo.agent import TeacherAgent
    from corn_drake.run_folders.config_file import load_run_config

    run = tmp_path / "run"
    common = ["train", "--policy", "state", "--envs-per-worker", "2", "--rollout-steps", "4",
              "--set", "task.episode_steps=5", "--no-progress", "--out", str(run)]
    assert main([*common, "--steps", "8", "--device", device]) == 0
    cfg = load_run_config(run)
    assert cfg.device == device
    saved = torch.load(run / "checkpoints" / "last.pt", weights_only=False)  # devices as saved
    assert len(list(_tensors(saved))) > 10
    assert all(t.device.type == "cpu" for t in _tensors(saved)), "a non-CPU tensor was saved"

    rng = np.random.default_rng(0)
    obs = {k: rng.standard_normal((3, *shape)) for k, shape in observation_shapes().items()}
    noise = rng.standard_normal((3, ACTION_DIM))
    on_cpu = TeacherAgent("state")
    on_cpu.load_saved_state(saved["agent"], "last.pt")
    rebuilt = Trainer(cfg, run).agent  # resumes from the checkpoint, on cfg.device
    assert rebuilt.log_std.device.type == device
    np.testing.assert_allclose(rebuilt.act(obs, noise), on_cpu.act(obs, noise),
                               rtol=0, atol=0 if device == "cpu" else 1e-5)

    other = "cpu:0" if device == "cpu" else "cpu"
    capsys.readouterr()
    assert main([*common, "--steps", "16", "--device", other]) == 0  # not refused
    assert f'device "{device}" -> "{other}"' in capsys.readouterr().out
    assert json.loads((run / "metrics.json").read_text())["global_step"] == 16


def _closed_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("", 0))
        return s.getsockname()[1]  # nothing listens there once this returns


@pytest.mark.parametrize("address", ["127.0.0.1:{closed}", "nonsense", "10.0.0.5:notaport"])
def test_scale_refuses_a_ray_address_nothing_answers_at(tmp_path, capsys, address):
    """Refused in one line naming --ray-address, exit 2, before any run (ray.init would retry
    such an address for minutes) and with no report written."""
    address = address.format(closed=_closed_port())
    path = tmp_path / "scale.json"
    assert main(["bench", "scale", "--report", str(path), "--ray-address", address]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert "--ray-address" in err and address in err, err
    assert not path.exists()


def test_scale_ray_address_reaches_every_runs_trainer_config(tmp_path, monkeypatch):
    """--ray-address is checked (something answers there: here a plain socket) and goes into
    the trainer's config (the Trainer joins that cluster: rl/training/ppo_trainer.py); no Ray started."""
    import socket

    from corn_drake.bench.training import timed_training

    configs = []

    def stop(cfg, *args, **kwargs):
        configs.append(cfg)
        raise InputError("stopped here")

    monkeypatch.setattr(timed_training, "run_trainer", stop)
    with socket.create_server(("", 0)) as server:
        address = f"127.0.0.1:{server.getsockname()[1]}"
        assert main(["bench", "scale", "--report", str(tmp_path / "s.json"), "--ray-address",
                     address, "--workers", "2"]) == 2
    assert [c.ray_address for c in configs] == [address]
    assert not (tmp_path / "s.json").exists()
    # Without it: a local Ray of the run's own, as before.
    configs.clear()
    assert main(["bench", "scale", "--report", str(tmp_path / "s.json")]) == 2
    assert [c.ray_address for c in configs] == [""]
