"""Output folders keep their data: refused resumes write nothing, one writer at a time, a corrupt
checkpoint falls back to the previous one, evaluate checks its destinations first, a library run
evaluates, and a killed driver leaves no Ray process behind."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from corn_drake.cli import main
from corn_drake.errors import InputError
from corn_drake.run_folders.config_file import load_run_config
from corn_drake.run_folders.guards import LOCK_NAME, lock_folder
from tests.fixtures import one_error_line, write_tiny_library
from tests.paths import REPO_ROOT

# A one-update state run: 2 envs x 16 steps, 10-step episodes.
TRAIN = ["train", "--policy", "state", "--envs-per-worker", "2", "--rollout-steps", "16",
         "--set", "task.episode_steps=10", "--no-progress"]
# Subprocesses must import this checkout's corn_drake, whatever the installed one is.
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), os.environ.get("PYTHONPATH", "")])}


def _files(folder: Path) -> dict[str, bytes]:
    """Every file under `folder` (the lock file aside: it is no output) with its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != LOCK_NAME}


@pytest.fixture(scope="module")
def state_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("runs") / "state"
    assert main([*TRAIN, "--steps", "32", "--out", str(run)]) == 0
    return run


# Evaluation on the run's env with 5-step episodes (a test needs the loop, not the skill).
SHORT_EPISODES = ["--set", "task.episode_steps=5"]


# --- issue 18 item 1: a refused resume leaves the run as it was -------------------------------
def test_train_refuses_changed_arguments_before_writing_and_extends_with_more_steps(
        state_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(state_run, run)
    before = _files(run)
    capsys.readouterr()
    assert main([*TRAIN, "--policy", "e2e", "--steps", "32", "--out", str(run)]) == 2
    one_error_line(capsys, str(run), "--policy: recorded 'state', requested 'e2e'")
    assert main([*TRAIN, "--seed", "3", "--set", "ppo.lr=1e-5", "--steps", "32",
                 "--out", str(run)]) == 2
    one_error_line(capsys, "--seed: recorded 0, requested 3", "--set ppo.lr: recorded 0.0003")
    assert main([*TRAIN, "--steps", "16", "--out", str(run)]) == 2  # fewer steps than done
    one_error_line(capsys, "--steps: recorded 32, requested 16")
    assert main(["train", "--set", "task.episode_steps=11", "--out", str(run)]) == 2
    one_error_line(capsys, "--task or --set task.episode_steps: recorded 10, requested 11")
    assert _files(run) == before  # config.yaml, checkpoint, metrics: all untouched
    # --steps may grow, and the recorded config is the rest: the run resumes from it with no
    # other argument, says what changed, and its config records the new total.
    capsys.readouterr()
    assert main(["train", "--resume", "--steps", "64", "--out", str(run), "--no-progress"]) == 0
    assert f"resume {run}: total_steps 32 -> 64\n" in capsys.readouterr().out
    resumed = load_run_config(run)
    assert resumed.total_steps == 64 and resumed.env.task.episode_steps == 10
    assert resumed.envs_per_worker == 2 and resumed.rollout_steps == 16
    assert json.loads((run / "metrics.json").read_text())["global_step"] == 64
    # Repeating the original arguments is no change either.
    assert main([*TRAIN, "--steps", "64", "--out", str(run)]) == 0
    assert f"resume {run}: as recorded\n" in capsys.readouterr().out


# --- item 11: a corrupt latest checkpoint falls back to the previous one ----------------------
def test_corrupt_checkpoint_falls_back_to_the_previous_then_is_named(
        state_run, tmp_path, capsys):
    from corn_drake.rl.training.ppo_trainer import Trainer

    run = tmp_path / "run"
    shutil.copytree(state_run, run)
    assert main([*TRAIN, "--steps", "64", "--out", str(run)]) == 0  # a second save: 32 -> prev.pt
    last, prev = run / "checkpoints" / "last.pt", run / "checkpoints" / "prev.pt"
    assert torch.load(prev, weights_only=False)["global_step"] == 32
    capsys.readouterr()
    with open(last, "r+b") as f:  # `truncate -s 1000 last.pt`
        f.truncate(1000)
    resumed = Trainer(load_run_config(run), run)
    assert resumed.global_step == 32
    err = capsys.readouterr().err
    assert "warning" in err and str(last) in err and str(prev) in err
    report = tmp_path / "ev.json"
    assert main(["evaluate", "--run", str(run), "--episodes", "1", "--record", "0",
                 *SHORT_EPISODES, "--report", str(report)]) == 0
    assert "previous checkpoint" in capsys.readouterr().err
    prev.write_bytes(b"not a checkpoint at all")
    before = _files(run)
    capsys.readouterr()
    assert main([*TRAIN, "--steps", "96", "--out", str(run)]) == 2
    one_error_line(capsys, str(last), str(prev))
    assert main(["evaluate", "--run", str(run), "--episodes", "1", "--record", "0",
                 "--report", str(report)]) == 2
    one_error_line(capsys, str(last))
    assert _files(run) == before


def test_checkpoint_save_keeps_the_previous_and_never_rotates_a_broken_one(tmp_path):
    from corn_drake.storage.checkpoint_files import load_checkpoint, save_checkpoint

    path = tmp_path / "checkpoints" / "last.pt"
    assert load_checkpoint(path) is None  # nothing to resume
    save_checkpoint(path, {"step": 1})
    save_checkpoint(path, {"step": 2})
    assert torch.load(path.with_name("prev.pt"))["step"] == 1
    path.write_bytes(b"\0" * 100)  # damaged after the fact: must not become prev.pt
    save_checkpoint(path, {"step": 3})
    assert torch.load(path.with_name("prev.pt"))["step"] == 1
    assert load_checkpoint(path, required=("step",))["step"] == 3
    with pytest.raises(InputError, match="missing"):
        load_checkpoint(path, required=("agent",))
    # Temporaries of saves killed mid-write (of last.pt and of its prev.pt copy) go at the next
    # save; another file's temporary in the folder is not this save's to remove.
    stale = [path.with_name(".last.pt.abc123.tmp"), path.with_name(".prev.pt.def456.tmp")]
    other = path.with_name(".step_000000100.pt.ghi789.tmp")
    for f in (*stale, other):
        f.write_bytes(b"partial")
    save_checkpoint(path, {"step": 4})
    assert not any(f.exists() for f in stale) and other.exists()
    assert load_checkpoint(path, required=("step",))["step"] == 4


# --- item 2: evaluate checks its destinations before any episode ------------------------------
@pytest.mark.parametrize("record", ["0", "1"])
def test_evaluate_refuses_an_unwritable_destination_before_any_episode(
        tmp_path, capsys, monkeypatch, record):
    from corn_drake.evaluation import episodes as evaluation

    def no_episode(*args, **kwargs):
        raise AssertionError("episodes ran before the destination was checked")

    monkeypatch.setattr(evaluation, "evaluate", no_episode)
    capsys.readouterr()
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    if record == "0":  # the report's folder cannot exist: a file has its name
        report = blocker / "ev.json"
    else:  # the report's folder is fine, its recordings folder cannot be made
        report = tmp_path / "ev.json"
        (tmp_path / "ev_recordings").write_text("")
    assert main(["evaluate", "--run", "still", "--episodes", "1", "--record", record,
                 "--report", str(report)]) == 2
    one_error_line(capsys, "--report" if record == "0" else "--record", "cannot write")


# --- item 3: one writer per output folder -----------------------------------------------------
def _wait_for(predicate, what: str) -> None:
    from tests.waiting import wait_until

    wait_until(predicate, what)  # no deadline: only a guard against a hang


def test_second_train_into_a_running_run_is_refused_and_a_killed_one_leaves_no_lock(tmp_path, capsys):
    run = tmp_path / "run"
    first = subprocess.Popen([sys.executable, "-m", "corn_drake.cli", *TRAIN, "--steps", "100000",
                              "--out", str(run)], env=ENV, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    try:
        # config.yaml is written once the first run holds the lock and passed its checks.
        _wait_for(lambda: (run / "config.yaml").is_file() or first.poll() is not None,
                  "the first run to start")
        assert first.poll() is None, "the first run ended early"
        capsys.readouterr()
        assert main([*TRAIN, "--steps", "64", "--out", str(run)]) == 2
        # Refused at once, not after waiting for the lock or training: while the first run
        # (100,000 steps, far from its end) still trains. The order of events, not a time a
        # busy machine could exceed.
        assert first.poll() is None, "the first run ended before the second was refused"
        one_error_line(capsys, str(run), "in use", str(first.pid))
    finally:
        first.send_signal(signal.SIGKILL)
        first.wait()
    with lock_folder(run):  # the kernel released the killed run's lock
        pass


@pytest.mark.parametrize("command", ["pretrain", "contact-data", "objects"])
def test_every_writing_command_refuses_a_locked_folder(tmp_path, capsys, command):
    out = tmp_path / "out"
    # The holder keeps the lock until the test kills it (a day's sleep): a sleep of a fixed
    # length would release it early on a machine busy enough to be slow.
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from corn_drake.run_folders.guards import lock_folder\n"
         "with lock_folder(sys.argv[1]):\n    print('locked', flush=True); time.sleep(86400)",
         str(out)],
        env=ENV, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        before = _files(out)
        lib = write_tiny_library(tmp_path / "lib")
        if command == "pretrain":  # its data is checked before the lock: give it real data
            from corn_drake.contact.runner import generate_dataset

            generate_dataset(lib, tmp_path / "data", num_samples=64, seed=0, eval_samples=32,
                             shard_size=64, progress=False)
        argv = {"pretrain": ["--data", str(tmp_path / "data"), "--steps", "2"],
                "contact-data": ["--objects", str(lib), "--num-samples", "64"],
                "objects": ["--num-objects", "1", "--drops", "8"]}[command]
        capsys.readouterr()
        assert main([command, *argv, "--out", str(out), "--no-progress"]) == 2
        one_error_line(capsys, str(out), "in use")
        assert _files(out) == before
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    with lock_folder(out):
        pass


# --- item 5: a resumed job with other arguments refuses, naming them --------------------------
def test_contact_data_refuses_another_seed_and_keeps_its_shards(tmp_path, capsys):
    lib, out = write_tiny_library(tmp_path / "lib"), tmp_path / "data"

    def contact_data(seed: int, shard_size: int = 64) -> int:
        return main(["contact-data", "--objects", str(lib), "--num-samples", "64",
                     "--eval-samples", "32", "--shard-size", str(shard_size), "--seed", str(seed),
                     "--out", str(out), "--no-progress"])

    assert contact_data(seed=0) == 0
    before = _files(out)
    capsys.readouterr()
    assert contact_data(seed=1) == 2
    one_error_line(capsys, str(out), "--seed: recorded 0, requested 1")
    assert _files(out) == before
    # A dataset made before arguments.json was kept is checked against its manifest.
    (out / "arguments.json").unlink()
    assert contact_data(seed=0, shard_size=128) == 2
    one_error_line(capsys, "--shard-size: recorded 64, requested 128")
    assert contact_data(seed=0) == 0  # the same arguments resume (nothing to redo)
    assert _files(out)["train/shard_00000.npz"] == before["train/shard_00000.npz"]


def test_objects_refuses_another_seed_and_grows_with_more_objects(tmp_path, capsys):
    out = tmp_path / "lib"
    args = ["objects", "--drops", "8", "--out", str(out), "--no-progress"]
    assert main([*args, "--num-objects", "1", "--seed", "0"]) == 0
    before = _files(out)
    capsys.readouterr()
    assert main([*args, "--num-objects", "1", "--seed", "1"]) == 2
    one_error_line(capsys, "--seed: recorded 0, requested 1")
    assert main([*args, "--num-objects", "1", "--drops", "9", "--seed", "0"]) == 2
    one_error_line(capsys, "--drops: recorded 8, requested 9")
    assert _files(out) == before
    assert main([*args, "--num-objects", "2", "--seed", "0"]) == 0
    assert len(json.loads((out / "manifest.json").read_text())["objects"]) == 2


# --- item 13: a run trained on a whole library evaluates over the library ---------------------
def test_evaluate_a_library_trained_run_over_the_requested_split(tmp_path):
    lib, run = tmp_path / "lib", tmp_path / "run"
    assert main(["objects", "--num-objects", "2", "--drops", "8", "--out", str(lib), "--no-progress"]) == 0
    train_ids = [o["id"] for o in json.loads((lib / "manifest.json").read_text())["objects"]
                 if o["split"] == "train"]
    assert len(train_ids) == 2
    assert main(["train", "--policy", "state", "--objects", str(lib), "--steps", "16",
                 "--envs-per-worker", "2", "--rollout-steps", "8", "--set", "task.episode_steps=5",
                 "--out", str(run), "--no-progress"]) == 0
    report = tmp_path / "ev.json"
    # No config argument: the run's config names its library (library_objects: train).
    assert main(["evaluate", "--run", str(run), "--split", "train", "--episodes", "2",
                 "--record", "0", "--report", str(report)]) == 0
    data = json.loads(report.read_text())
    assert sorted(data["per_object"]) == sorted(train_ids)  # round-robin over both objects
    assert all(e["steps"] <= 5 for e in data["episodes"])  # the run's episode length


# --- item 16: a killed driver's local Ray ends with it ----------------------------------------
DRIVER = """
import ray
from corn_drake.rl.workers.ray_workers import init_ray
init_ray(num_cpus=1)
@ray.remote(num_cpus=0)
def pid():
    import os
    return os.getpid()
ray.get(pid.remote())
print("ready", flush=True)
import time
time.sleep(86400)  # until the test kills it, however long Ray's agents take to start
"""


def test_killed_driver_leaves_no_ray_process_behind():
    psutil = pytest.importorskip("psutil")
    driver = subprocess.Popen([sys.executable, "-c", DRIVER], env=ENV, stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, text=True)
    started = []
    try:
        assert driver.stdout.readline().strip() == "ready"
        tree = psutil.Process(driver.pid)

        def agents_up():
            started[:] = tree.children(recursive=True)
            return any("Agent" in " ".join(p.cmdline()) for p in started if p.is_running())

        _wait_for(agents_up, "Ray's agents to start")  # what used to outlive the driver
        time.sleep(0.5)
        driver.send_signal(signal.SIGKILL)
        driver.wait()
        # They end on their own (the reaper): wait for that, however slow a busy machine is;
        # a process still running at the hang guard's cap outlived its driver.
        _wait_for(lambda: not any(_running(p) for p in started),
                  "Ray's processes to end after the driver's death")
    finally:
        if driver.poll() is None:
            driver.kill()
            driver.wait()
        for p in started:  # only what this test's driver started
            if _running(p):
                p.kill()


def _running(process) -> bool:
    import psutil

    try:
        return process.is_running() and process.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def test_a_failure_before_any_output_leaves_no_trace_but_one_after_keeps_the_record(tmp_path):
    from corn_drake.run_folders.guards import resume_arguments

    fresh = tmp_path / "fresh"
    with pytest.raises(RuntimeError):
        with lock_folder(fresh):
            resume_arguments(fresh, {"--seed": 0}, made_by="contact-data")
            raise RuntimeError("bad input found after the lock")
    assert not fresh.exists()  # the folder it made is gone with its bookkeeping
    started = tmp_path / "started"
    with pytest.raises(RuntimeError):
        with lock_folder(started):
            resume_arguments(started, {"--seed": 0}, made_by="contact-data")
            (started / "shard_0.npz").write_bytes(b"partial output")
            raise RuntimeError("killed mid-way")
    # Real output exists: the argument record stays, so a resume is checked against it.
    assert (started / "arguments.json").is_file() and (started / "shard_0.npz").is_file()


@pytest.mark.parametrize("recorded, maker", [
    ({"made_by": "contact-data", "--seed": 0}, "contact-data"),
    # Records from before they named their command: known by the arguments only it records.
    ({"--source": "procedural", "--seed": 0}, "objects"),
    ({"--objects": "lib", "--num-samples": 8}, "contact-data"),
    ({"--data": "data/contact"}, "pretrain"),
])
def test_a_folder_another_command_made_is_refused_naming_it(tmp_path, recorded, maker):
    """Ownership (issue 63): a resumable command writes only into a new or empty folder, or one
    it made; another command's folder, or one holding what no command recorded, is named."""
    import json

    from corn_drake.errors import InputError
    from corn_drake.run_folders.guards import resume_arguments

    folder = tmp_path / "theirs"
    folder.mkdir()
    (folder / "arguments.json").write_text(json.dumps(recorded))
    other = "objects" if maker != "objects" else "pretrain"
    with pytest.raises(InputError, match=f"holds the output of `corn-drake {maker}`"):
        resume_arguments(folder, {"--seed": 0}, made_by=other)
    assert json.loads((folder / "arguments.json").read_text()) == recorded  # left as it was
    resume_arguments(folder, {"--seed": 0}, made_by=maker)  # its own: resumed
    assert json.loads((folder / "arguments.json").read_text())["made_by"] == maker
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yaml").write_text("policy: state\n")
    with pytest.raises(InputError, match="holds a run .config.yaml., which `corn-drake objects`"):
        resume_arguments(run, {"--seed": 0}, made_by="objects")
    # Without a record, a folder holding this command's own older output is its own.
    library = tmp_path / "older_library"
    library.mkdir()
    (library / "manifest.json").write_text("{}")
    resume_arguments(library, {"--seed": 0}, made_by="objects",
                     holds_own=lambda f: (f / "manifest.json").is_file())


def test_a_failure_before_any_output_removes_the_parents_it_made_and_only_those(tmp_path):
    kept = tmp_path / "runs"
    kept.mkdir()
    (kept / "other_run").mkdir()  # the user's: stays
    deep = kept / "new" / "deeper" / "run"
    with pytest.raises(RuntimeError):
        with lock_folder(deep):
            assert deep.is_dir()
            raise RuntimeError("bad input found after the lock")
    assert not (kept / "new").exists() and (kept / "other_run").is_dir()


@pytest.mark.parametrize("argv", [
    ["train", "--policy", "state", "--task", "nosuch_task", "--out", "{out}"],
    ["train", "--out", "{out}"],  # corn, the default policy, without --encoder
    ["contact-data", "--objects", "{root}/nowhere", "--num-samples", "8", "--out", "{out}"],
    ["objects", "--source", "{root}/nowhere", "--out", "{out}", "--no-progress"],
    ["pretrain", "--model", "rot", "--objects", "{root}/nowhere", "--out", "{out}"],
    ["pretrain", "--model", "corn", "--data", "{root}/nowhere", "--out", "{out}"],
])
def test_a_refused_command_leaves_no_folder_behind(tmp_path, capsys, argv):
    """Issue 36: `train` refused for a bad --task left an empty runs/ behind."""
    out = tmp_path / "runs" / "new_run"
    assert main([a.format(out=out, root=tmp_path) for a in argv]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []
