"""The per-node cache of object libraries that reached a Ray worker through the object store
(rl/workers/node_library_cache.py, issue 56): written once, and removed once unused for a day unless a live
process holds it. No Ray: folders, locks and mtimes only."""

import os
import subprocess
import sys
import time

from corn_drake.rl.workers import cluster, node_library_cache
from corn_drake.rl.workers.node_library_cache import CACHE_UNUSED_S, node_copy, prune_library_cache
from tests.fixtures import write_loadable_library

DAY = CACHE_UNUSED_S


def _cached(root, name, age_s, lock=True):
    folder = root / name
    folder.mkdir(parents=True)
    (folder / "manifest.json").write_text("{}")
    (folder / ".checked").write_text("")
    then = time.time() - age_s
    os.utime(folder, (then, then))
    if lock:
        (root / f"{name}.lock").touch()
        os.utime(root / f"{name}.lock", (then, then))
    return folder


def test_libraries_unused_for_a_day_go_and_the_rest_stay(tmp_path):
    root = tmp_path / "corn_drake_libraries"
    _cached(root, "in_use", 3 * DAY)  # the one the caller unpacks now: kept however old
    _cached(root, "old", DAY + 60)
    _cached(root, "old_without_lock", 2 * DAY, lock=False)  # a cache older than the locks
    _cached(root, "recent", DAY - 60)
    writing = root / ".arriving-abc"  # another worker writing a library now
    writing.mkdir()
    abandoned = root / ".arriving-killed"  # what a killed worker left
    abandoned.mkdir()
    old = time.time() - 2 * DAY
    os.utime(abandoned, (old, old))
    removed = prune_library_cache(root, keep="in_use")
    assert sorted(removed) == [".arriving-killed", "old", "old_without_lock"]
    assert sorted(p.name for p in root.iterdir()) == [".arriving-abc", "in_use", "in_use.lock",
                                                      "recent", "recent.lock"]


def test_a_library_a_live_process_holds_is_never_removed(tmp_path):
    """Held (a shared flock on its lock file, as every worker holds its library for its life):
    kept however old; once the holder is gone, removed."""
    root = tmp_path / "libs"
    _cached(root, "held", 5 * DAY)
    holder = subprocess.Popen(
        [sys.executable, "-c",
         "import fcntl, os, sys; fd = os.open(sys.argv[1], os.O_RDWR); "
         "fcntl.flock(fd, fcntl.LOCK_SH); print('held', flush=True); sys.stdin.read()",
         str(root / "held.lock")], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        assert prune_library_cache(root, keep="other") == []
        assert (root / "held" / ".checked").exists()
    finally:
        holder.communicate("", timeout=30)
    assert prune_library_cache(root, keep="other") == ["held"]
    assert not any(root.iterdir())


def test_an_arriving_library_is_written_held_touched_and_prunes_the_stale_ones(tmp_path):
    from corn_drake.assets.content_hash import object_hashes
    from corn_drake.assets.manifest import read_manifest

    library = write_loadable_library(tmp_path / "lib", 1, num_unseen=0)
    ids = [o.id for o in read_manifest(library).objects]
    files = {p.relative_to(library).as_posix(): p.read_bytes()
             for p in library.rglob("*") if p.is_file()}
    packed = cluster.LibraryFiles("driver", str(library), files, object_hashes(library, ids),
                                  digest="ab" * 32)
    root = tmp_path / "cache"
    stale = _cached(root, "stale", 2 * DAY)
    folder = node_copy(packed, root)
    assert folder == root / ("ab" * 12) and (folder / ".checked").exists()
    assert not stale.exists()  # unused for two days: removed by this arrival
    assert time.time() - folder.stat().st_mtime < 60  # touched: used now
    # This process holds it: another arrival elsewhere cannot remove it, even once it is old.
    assert root / f"{'ab' * 12}.lock" in node_library_cache._held_locks
    old = time.time() - 3 * DAY
    os.utime(folder, (old, old))
    os.utime(root / f"{'ab' * 12}.lock", (old, old))
    assert prune_library_cache(root, keep="another") == []
    # A second arrival of the same content reuses the folder (no rewrite) and touches it again.
    (folder / "marker").write_text("")
    assert node_copy(packed, root) == folder and (folder / "marker").exists()
    assert time.time() - folder.stat().st_mtime < 60
