"""`corn-drake collect-outcomes` and `corn-drake fit-outcome`, the two commands that built the
shipped full6d_outcome policy's data and model: a fit is reproducible bit for bit and the CLI
gives what the library gives; bad inputs are refused in one line with nothing written; a
collection writes its chunk and a rerun skips it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from corn_drake.cli import main
from tests.fixtures import one_error_line

REPO = Path(__file__).resolve().parents[1]
PROPOSING_RUN = REPO / "models" / "weights" / "push_turn_primitive"
CORNERS = np.array([[x, y, z] for x in (-0.05, 0.05) for y in (-0.03, 0.03)
                    for z in (-0.02, 0.02)])
LOCATIONS, PER_STATE = 16, 6


def write_chunk(path: Path, states: int, objects: list[str], seed: int) -> None:
    """One collect-format file (collect.collect_chunks' keys) of `states` states spread over
    `objects`, in a world where a push carries the object half the push's planar length."""
    rng = np.random.default_rng(seed)
    pose = np.concatenate([np.c_[rng.uniform(-0.1, 0.1, (states, 2)), np.full(states, 0.43)],
                           np.tile([1.0, 0, 0, 0], (states, 1))], 1)
    goal = pose.copy()
    goal[:, :2] += 0.1
    state = np.repeat(np.arange(states), PER_STATE)
    motion = rng.uniform(-1, 1, (len(state), 3)).astype(np.float32)
    after = pose[state].copy()
    after[:, :2] += 0.5 * 0.15 * motion[:, :2]
    local = np.zeros((states, LOCATIONS, 9), np.float32)
    local[..., 6] = 1.0
    np.savez(path, state=state, location=rng.integers(0, LOCATIONS, len(state)), motion=motion,
             reward=rng.normal(0, 0.1, len(state)).astype(np.float32),
             features_tokens=rng.normal(size=(states, LOCATIONS, 4)).astype(np.float32),
             features_local=local, features_global=np.zeros((states, 8), np.float32),
             features_mask=np.ones((states, LOCATIONS), np.float32),
             outcome_pose=pose, outcome_goal=goal,
             outcome_corners=np.repeat(CORNERS[None], states, 0),
             outcome_aims=np.repeat(pose[:, None, :3], LOCATIONS, 1),
             outcome_physics=np.ones((states, 5)), pose_after=after,
             still_after=np.ones(len(state), bool), success_after=np.zeros(len(state), bool),
             episode=np.arange(states) // 2,
             object=np.array([objects[i % len(objects)] for i in range(states)]))


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> list[Path]:
    """Two collect folders whose object ids coincide (libraries of other seeds)."""
    root = tmp_path_factory.mktemp("outcome_data")
    folders = [root / "a", root / "b"]
    for i, folder in enumerate(folders):
        folder.mkdir()
        for k in range(2):
            write_chunk(folder / f"episodes_{10 * k:05d}.npz", 4, ["box_00", "cyl_01"],
                        seed=10 * i + k)
    return folders


def _weights(path: Path) -> dict:
    return torch.load(path, map_location="cpu", weights_only=False)["model"]


def _fit_cli(data, out: Path, *extra: str) -> int:
    return main(["fit-outcome", str(PROPOSING_RUN), "--data", *map(str, data), "--out", str(out),
                 "--updates", "40", *extra])


def test_a_fit_repeats_bit_for_bit_and_the_cli_gives_the_librarys_model(data, tmp_path):
    from corn_drake.rl.primitive.outcome.fit import fit_outcome

    first, second, library = tmp_path / "1.pt", tmp_path / "2.pt", tmp_path / "lib.pt"
    assert _fit_cli(data, first, "--seed", "3") == 0
    assert _fit_cli(data, second, "--seed", "3") == 0
    facts = fit_outcome(PROPOSING_RUN, data, out=library, seed=3, updates=40)
    a, b, c = _weights(first), _weights(second), _weights(library)
    assert a.keys() == b.keys() == c.keys()
    for key in a:
        assert torch.equal(a[key], b[key]) and torch.equal(a[key], c[key]), key
    assert facts["states"] == 16 and facts["rows"] == 16 * PER_STATE and len(
        facts["fit_history"]) == 1
    # Another seed lands elsewhere: the comparison above can fail.
    assert _fit_cli(data, tmp_path / "other.pt", "--seed", "4") == 0
    other = _weights(tmp_path / "other.pt")
    assert any(not torch.equal(a[k], other[k]) for k in a)
    # A fitted model is not replaced by another fit unless --overwrite says so (issue 63).
    before = first.read_bytes()
    assert _fit_cli(data, first, "--seed", "4") == 2 and first.read_bytes() == before
    assert _fit_cli(data, first, "--seed", "4", "--overwrite") == 0
    assert any(not torch.equal(a[k], _weights(first)[k]) for k in a)


def test_objects_fits_the_states_of_that_many_objects(data, tmp_path):
    from corn_drake.rl.primitive.outcome.fit import fit_outcome

    # Tagged by folder, the two folders hold four objects of four states each.
    facts = fit_outcome(PROPOSING_RUN, data, out=tmp_path / "m.pt", objects=2, updates=5)
    assert facts["objects"] == 2 and facts["states"] == 8
    saved = torch.load(tmp_path / "m.pt", map_location="cpu", weights_only=False)
    assert saved["objects"] == 2 and saved["input_kind"] == "raw"


def test_out_run_writes_a_run_folder_that_chooses_by_the_model(data, tmp_path, capsys):
    from corn_drake.config.primitive import PrimitiveTrainConfig
    from corn_drake.config.plumbing.loader import load_config
    from corn_drake.run_folders.config_file import run_config_path

    out = tmp_path / "run"
    assert main(["fit-outcome", str(PROPOSING_RUN), "--data", *map(str, data), "--out-run",
                 str(out), "--task", "full6d", "--set", "primitive.max_primitives=15",
                 "--inputs", "box_contact", "--updates", "5"]) == 0
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()) == [
        "checkpoints/last.pt", "config.yaml", "outcome_model.pt"]
    cfg = load_config(PrimitiveTrainConfig, run_config_path(out))
    assert cfg.chooser == "outcome_model" and cfg.primitive.max_primitives == 15
    assert cfg.env.task.name == "full6d"
    assert torch.load(out / "outcome_model.pt", weights_only=False)["input_kind"] == "box_contact"
    assert f"wrote {out}" in capsys.readouterr().out


def _bad_cases(data: list[Path], tmp_path: Path) -> dict:
    empty, stale = tmp_path / "empty", tmp_path / "stale"
    empty.mkdir()
    stale.mkdir()
    np.savez(stale / "episodes_00000.npz", state=np.zeros(1, np.int64),
             features_tokens=np.zeros((1, 16, 4), np.float32))  # collected before outcomes
    taken = tmp_path / "taken"
    taken.mkdir()
    good = ["--data", *map(str, data)]
    return {
        "missing data folder": (["--data", str(tmp_path / "nowhere"), "--out", "m.pt"],
                                "nowhere: no such folder"),
        "empty data folder": (["--data", str(empty), "--out", "m.pt"], "no episodes_*.npz"),
        "data without outcomes": (["--data", str(stale), "--out", "m.pt"], "files without"),
        "objects out of range": ([*good, "--objects", "9", "--out", "m.pt"],
                                 "--objects 9: the data have 4 objects"),
        "existing out-run": ([*good, "--out-run", str(taken)], "exists"),
        "bad task": ([*good, "--out-run", "new", "--task", "nosuchtask"], "nosuchtask"),
        "bad set": ([*good, "--out-run", "new", "--set", "primitive.nosuchfield=1"],
                    "nosuchfield"),
        "no output": (good, "--out"),
    }


@pytest.mark.parametrize("case", ["missing data folder", "empty data folder",
                                  "data without outcomes", "objects out of range",
                                  "existing out-run", "bad task", "bad set", "no output"])
def test_bad_input_is_refused_in_one_line_and_nothing_is_written(case, data, tmp_path, capsys,
                                                                 monkeypatch):
    monkeypatch.chdir(tmp_path)
    args, needle = _bad_cases(data, tmp_path)[case]
    before = sorted(p for p in tmp_path.rglob("*"))
    assert main(["fit-outcome", str(PROPOSING_RUN), *args, "--updates", "5"]) == 2
    one_error_line(capsys, needle)
    assert sorted(p for p in tmp_path.rglob("*")) == before


def test_the_cli_lists_both_commands():
    out = subprocess.run([sys.executable, "-m", "corn_drake.cli", "--help"], cwd=REPO,
                         capture_output=True, text=True, check=True).stdout
    assert "collect-outcomes" in out and "fit-outcome" in out


def test_collect_outcomes_writes_a_chunk_and_a_rerun_skips_it(tmp_path, capsys):
    from tests.fixtures import write_loadable_library

    from corn_drake.rl.primitive.outcome.data import load_outcome_data

    library = write_loadable_library(tmp_path / "lib", 1, num_unseen=0)
    out = tmp_path / "data"
    args = ["collect-outcomes", str(PROPOSING_RUN), "--objects", str(library), "--episodes", "1",
            "--chunk", "1", "--random-motions", "0", "--at-rest", "--set",
            "primitive.max_primitives=1", "--out", str(out)]
    assert main(args) == 0
    chunk = out / "episodes_00000.npz"
    assert sorted(p.name for p in out.iterdir()) == [chunk.name, "inputs.json"]
    assert '"episode": 0' in capsys.readouterr().out
    data = load_outcome_data([out])
    assert len(data["features_tokens"]) == 1 and set(data["object"]) == {"0:box_00"}
    assert len(data["reward"]) >= 1 and data["episode"].tolist() == [0]
    stamp = chunk.stat().st_mtime_ns
    assert main(args) == 0
    assert chunk.stat().st_mtime_ns == stamp and "wrote 0 file(s)" in capsys.readouterr().out
    # More episodes of other settings into the same folder would mix data: refused, named.
    other = [*args[:-2], "--start", "1", "--at-rest", "--out", str(out)]
    other[other.index("--random-motions") + 1] = "2"
    assert main(other) == 2
    err = capsys.readouterr().err
    assert "random_motions: 0 then, 2 now" in err and "mix" in err
    assert sorted(p.name for p in out.iterdir()) == [chunk.name, "inputs.json"]


def test_collect_outcomes_refuses_a_library_without_training_objects(tmp_path, capsys):
    from tests.fixtures import write_loadable_library

    library = write_loadable_library(tmp_path / "lib", 0, num_unseen=1)
    assert main(["collect-outcomes", str(PROPOSING_RUN), "--objects", str(library),
                 "--episodes", "1", "--out", str(tmp_path / "data")]) == 2
    one_error_line(capsys, "no training objects")
    assert not (tmp_path / "data").exists()


@pytest.mark.slow
def test_collect_outcomes_over_ray_workers_writes_the_same_chunks(tmp_path, capsys):
    """`collect-outcomes --workers 2`: the chunks collected in two Ray worker processes (the
    objects sent through the object store) are the files one process writes: the same episodes,
    objects, states and candidates, the same outcomes up to rounding; a rerun writes nothing."""
    import ray

    from tests.fixtures import write_loadable_library

    from corn_drake.rl.primitive.outcome.data import load_outcome_data

    library = write_loadable_library(tmp_path / "lib", 2, num_unseen=0)
    argv = ["collect-outcomes", str(PROPOSING_RUN), "--objects", str(library), "--episodes", "2",
            "--chunk", "1", "--random-motions", "1", "--set", "primitive.max_primitives=1"]
    try:
        assert main([*argv, "--out", str(tmp_path / "one")]) == 0
        assert main([*argv, "--workers", "2", "--out", str(tmp_path / "two")]) == 0
        names = lambda d: sorted(p.name for p in (tmp_path / d).iterdir())  # noqa: E731
        assert names("one") == names("two") == [
            "episodes_00000.npz", "episodes_00001.npz", "inputs.json"]
        one, two = load_outcome_data([tmp_path / "one"]), load_outcome_data([tmp_path / "two"])
        assert one.keys() == two.keys()
        for key in ("episode", "object", "state", "location"):
            assert one[key].tolist() == two[key].tolist(), key
        for key in ("reward", "motion", "features_tokens", "pose_after"):
            assert np.allclose(one[key], two[key], atol=1e-5), key
        capsys.readouterr()
        assert main([*argv, "--workers", "2", "--out", str(tmp_path / "two")]) == 0
        assert "wrote 0 file(s)" in capsys.readouterr().out
    finally:
        ray.shutdown()


def test_collect_outcomes_ray_address_needs_workers(tmp_path, capsys):
    assert main(["collect-outcomes", str(PROPOSING_RUN), "--ray-address", "auto",
                 "--out", str(tmp_path / "data")]) == 2
    one_error_line(capsys, "--ray-address needs --workers")
    assert not (tmp_path / "data").exists()
