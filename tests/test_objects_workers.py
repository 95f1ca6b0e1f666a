"""`corn-drake objects --workers N` builds the library a serial build does, every file byte for
byte (build_timings.json, the measured wall times, aside); a failing object is named in one line
with the objects before it kept; a resume (and its progress bar) counts only what is left.

The library code and tests.fixtures (numpy) are imported inside the tests: the spawned pool
workers of the pool tests import this module for its item functions, and must start with nothing
that sizes a thread pool loaded."""

import hashlib
import json
import os
from pathlib import Path

import pytest

from corn_drake.cli import main

# Block, book, bottle and bowl: the first four objects of every procedural build (all concave,
# so CoACD and its cache are covered too); 6 drops each keeps one object to a few seconds.
SMALL = ["objects", "--num-objects", "4", "--seed", "0", "--drops", "6", "--no-progress"]


def _files(library: Path) -> dict[str, str]:
    """sha256 of every file under `library` (the manifest, the argument record, the lock and the
    CoACD cache included) but the measured wall times."""
    return {str(p.relative_to(library)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(library.rglob("*"))
            if p.is_file() and p.name != "build_timings.json"}


@pytest.mark.slow
def test_two_workers_build_the_serial_library_even_across_a_failure(tmp_path, capsys):
    from tests.fixtures import one_error_line

    serial, pool = tmp_path / "serial", tmp_path / "pool"
    assert main([*SMALL, "--out", str(serial)]) == 0
    # A file where book_000's folder goes: its build fails in a worker, after block_000 ran.
    # The folder is this command's (its record of the arguments, as a killed first run of the
    # same command leaves it): a folder holding anything else is not objects' to build in.
    pool.mkdir()
    (pool / "arguments.json").write_bytes((serial / "arguments.json").read_bytes())
    (pool / "book_000").write_text("in the way")
    assert main([*SMALL, "--workers", "2", "--out", str(pool)]) == 2
    one_error_line(capsys, "object book_000", "FileExistsError")
    kept = json.loads((pool / "manifest.json").read_text())
    assert [o["id"] for o in kept["objects"]] == ["block_000"]  # finished before it: saved
    # The same command resumes from the failed object once its cause is gone.
    (pool / "book_000").unlink()
    assert main([*SMALL, "--workers", "2", "--out", str(pool)]) == 0
    assert (pool / "build_timings.json").is_file()
    serial_files = _files(serial)
    assert "manifest.json" in serial_files and ".coacd_cache" in "".join(serial_files)
    assert sorted(serial_files) == sorted(_files(pool))
    assert serial_files == _files(pool)
    manifest = json.loads((pool / "manifest.json").read_text())
    assert [o["id"] for o in manifest["objects"]] == ["block_000", "book_000", "bottle_000",
                                                      "bowl_000"]


def _fake_build(out, seed, cfg, planned):
    """_build_planned's result without the mesh work: the object, or a rejection for bowls."""
    from corn_drake.assets.library import _procedural_source
    from corn_drake.assets.manifest import LibraryObject, Rejection

    source = _procedural_source(seed, planned)
    if planned.family == "bowl":
        return Rejection(source, "rejected by the test"), {}
    return LibraryObject(id=planned.id, family=planned.family, source=source), {"total_s": 0.0}


def test_a_resume_counts_only_the_objects_left(tmp_path, monkeypatch):
    import tqdm

    from corn_drake.assets import library

    totals = []
    real_tqdm = tqdm.tqdm

    def recording_tqdm(iterable, total=None, **kwargs):
        totals.append(total)
        return real_tqdm(iterable, total=total, **kwargs)

    monkeypatch.setattr(library, "_build_planned", _fake_build)
    monkeypatch.setattr(tqdm, "tqdm", recording_tqdm)
    # Left by a worker stopped mid-object: cleared before the object is built again.
    stale = [tmp_path / "block_000" / ".cloud.npy.x1.tmp",
             tmp_path / ".coacd_cache" / ".k.npz.x2.tmp"]
    for path in stale:
        path.parent.mkdir(parents=True)
        path.write_text("half written")
    library.build_procedural(tmp_path, 4, seed=0, progress=False)  # block, book, bottle, bowl
    assert not any(path.exists() for path in stale)
    manifest = library.read_manifest(tmp_path)
    assert manifest.ids() == ["block_000", "book_000", "bottle_000"]
    assert len(manifest.rejected) == 1  # bowl_000
    # Growing to 6 (capsule, convex_hull): the bar counts those two, not the 4 done or rejected.
    library.build_procedural(tmp_path, 6, seed=0, progress=False)
    manifest = library.read_manifest(tmp_path)
    assert totals == [4, 2]
    assert manifest.ids()[-2:] == ["capsule_000", "convex_hull_000"]
    assert len(manifest.rejected) == 1  # the bowl was not built (and rejected) again


def test_objects_to_build_skips_built_rejected_and_other_split_objects():
    from corn_drake.assets.library import _procedural_source, objects_to_build, planned_procedural
    from corn_drake.assets.manifest import Manifest, Rejection

    planned = planned_procedural(6)
    done = Manifest(objects=[planned[0]],
                    rejected=[Rejection(_procedural_source(3, planned[2]), "no stable pose")])
    assert [o.id for o in objects_to_build(planned, done, seed=3)] == \
        [planned[i].id for i in (1, 3, 4, 5)]
    wanted = {planned[i].id for i in (0, 2, 4)}
    assert [o.id for o in objects_to_build(planned, done, 3, wanted)] == [planned[4].id]
    # A rejection is matched by source, which depends on the seed.
    assert planned[2] in objects_to_build(planned, done, seed=4)


@pytest.mark.parametrize("value", ["0", "-2", "1.5", "two"])
def test_workers_must_be_a_positive_count(value, tmp_path, capsys):
    from tests.fixtures import one_error_line

    with pytest.raises(SystemExit) as e:
        main(["objects", "--workers", value, "--out", str(tmp_path / "lib")])
    assert e.value.code == 2
    one_error_line(capsys, "argument --workers", "an integer >= 1", repr(value))
    assert not (tmp_path / "lib").exists()


def test_workers_are_refused_for_a_mesh_folder(tmp_path, capsys):
    from tests.fixtures import one_error_line

    meshes = tmp_path / "meshes"
    meshes.mkdir()
    assert main(["objects", "--source", str(meshes), "--workers", "2",
                 "--out", str(tmp_path / "lib")]) == 2
    one_error_line(capsys, "--workers 2", "--source")
    assert not (tmp_path / "lib").exists()


# --- the pool itself (assets/build_pool.py), with cheap items --------------------------------
def _upper_or_fail(item: str) -> str:
    if item == "c":
        raise RuntimeError("c is broken\nsecond line of the message")
    if item == "die":
        os._exit(3)  # a worker killed outright (out of memory, a segfault)
    return item.upper()


def _collect(todo, workers):
    """(what in_plan_order yielded before it raised, the error or None)."""
    from corn_drake.assets.build_pool import in_plan_order

    got = []
    try:
        for result in in_plan_order(_upper_or_fail, todo, workers, name=str):
            got.append(result)
    except Exception as e:  # noqa: BLE001 - the test looks at it
        return got, e
    return got, None


@pytest.mark.parametrize("workers", [1, 2])
def test_a_failing_item_is_named_after_those_before_it(workers):
    from corn_drake.assets.build_pool import ObjectBuildError

    assert _collect(["b", "a", "d", "e"], workers) == (["B", "A", "D", "E"], None)  # plan order
    got, error = _collect(["a", "b", "c", "d"], workers)
    assert got == ["A", "B"] and isinstance(error, ObjectBuildError)
    message = str(error)
    assert "object c:" in message and "RuntimeError: c is broken" in message
    assert "\n" not in message and "second line" not in message


def test_a_dead_worker_is_named_not_waited_for():
    from corn_drake.assets.build_pool import ObjectBuildError

    got, error = _collect(["die", "a"], workers=2)
    assert got == [] and isinstance(error, ObjectBuildError)
    assert "object die:" in str(error) and "BrokenProcessPool" in str(error)


def _fail_or_finish_late(item):
    """("fail", _) raises at once; ("late", MARKER) writes MARKER after 30 s, unless stopped."""
    import time

    kind, marker = item
    if kind == "fail":
        raise RuntimeError("fails at once")
    time.sleep(30)
    Path(marker).write_text("finished")


def test_a_failure_stops_the_other_workers_at_once(tmp_path):
    """Nothing a worker makes after a failure can be saved (plan order): its object is not
    finished (the marker), it is stopped, not waited for."""
    from corn_drake.assets.build_pool import ObjectBuildError, in_plan_order

    marker = tmp_path / "late_finished"
    todo = [("fail", None), ("late", str(marker))]
    with pytest.raises(ObjectBuildError, match="object fail: .*fails at once"):
        list(in_plan_order(_fail_or_finish_late, todo, workers=2, name=lambda i: i[0]))
    assert not marker.exists()


def _threads_after_numpy(_item):
    """(OMP_NUM_THREADS, whether numpy was loaded already, the threads its import started) in
    the worker running this."""
    import sys

    def threads():
        return len(os.listdir("/proc/self/task"))

    loaded, before = "numpy" in sys.modules, threads()
    import numpy  # noqa: F401 - OpenBLAS sizes its thread pool here, to the CPUs unless told

    return os.environ.get("OMP_NUM_THREADS"), loaded, threads() - before


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads in /proc")
def test_pool_workers_are_single_threaded():
    from corn_drake.assets.build_pool import in_plan_order

    results = list(in_plan_order(_threads_after_numpy, [0, 1], workers=2, name=str))
    assert results == [("1", False, 0), ("1", False, 0)]
