"""The per-node cache of object libraries that reach Ray workers through the object store
(rl/workers/cluster.arrive): $TMPDIR/corn_drake_libraries/<digest>/, one folder per library
content, written once per node, every object checked by content hash, and removed a day after
its last use by a later worker on that node (the rule above CACHE_UNUSED_S)."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import time
from pathlib import Path

# The per-node library cache: $TMPDIR/corn_drake_libraries/<digest>/, one folder per library
# content. Its rule: a worker that unpacks a library on a node removes that node's other cached
# libraries that no live worker holds and no worker unpacked for CACHE_UNUSED_S (a day; the
# folder's mtime, touched on every arrival). Every worker holds a shared flock on
# <digest>.lock for its life and the remover needs the exclusive one, so a library a running
# worker reads is never removed, however long the run; one removed after its run ended is
# written again by the next run that ships it. A folder appears only by the atomic rename of a
# private `.arriving-*` folder, so a library being written is never a candidate; an
# `.arriving-*` or `.removing-*` folder a day old is what a killed worker left, and goes too.
CACHE_UNUSED_S = 24 * 3600.0

# The shared locks this process holds on the cached libraries it uses (kept for its life).
_held_locks: dict[Path, int] = {}


def library_cache_root() -> Path:
    return Path(tempfile.gettempdir()) / "corn_drake_libraries"


def _lock_path(root: Path, name: str) -> Path:
    return root / f"{name}.lock"


def _locked(path: Path, mode: int) -> int | None:
    """An open descriptor of `path` (created if missing) holding flock `mode`, or None when a
    non-blocking `mode` is refused. Retries while the file it locked was removed (a remover
    unlinks it under its exclusive lock): a lock on an unlinked file guards nothing."""
    import fcntl

    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, mode)
        except BlockingIOError:
            os.close(fd)
            return None
        with contextlib.suppress(FileNotFoundError):
            if os.stat(path).st_ino == os.fstat(fd).st_ino:
                return fd
        os.close(fd)


def _hold(root: Path, name: str) -> None:
    """A shared lock on cached library `name` for the rest of this process (a worker's life):
    no remover takes it while this process may read it."""
    import fcntl

    path = _lock_path(root, name)
    if path not in _held_locks:
        _held_locks[path] = _locked(path, fcntl.LOCK_SH)


def prune_library_cache(root: Path, keep: str, now: float | None = None) -> list[str]:
    """Removes the cached libraries in `root` (all but `keep`) unused for CACHE_UNUSED_S that no
    process holds (the rule above); returns their names. Best effort: whatever cannot be
    removed stays for a later worker."""
    import fcntl

    now = time.time() if now is None else now
    old = now - CACHE_UNUSED_S
    removed = []
    names = {p.name.removesuffix(".lock") for p in root.iterdir()
             if not p.name.startswith(".") and p.name != keep and p.name != f"{keep}.lock"}
    for name in sorted(names):
        folder, lock = root / name, _lock_path(root, name)
        with contextlib.suppress(OSError):
            if max(_mtime(folder), _mtime(lock)) > old:
                continue
            fd = _locked(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            if fd is None:  # a live worker reads it
                continue
            try:
                if _mtime(folder) > old:  # used between the look and the lock
                    continue
                if folder.exists():
                    doomed = Path(tempfile.mkdtemp(prefix=".removing-", dir=root))
                    os.rename(folder, doomed / name)
                    shutil.rmtree(doomed, ignore_errors=True)
                os.unlink(lock)
                removed.append(name)
            finally:
                os.close(fd)
    for leftover in root.iterdir():  # .arriving-* / .removing-* a killed worker left
        if leftover.name.startswith((".arriving-", ".removing-")) and _mtime(leftover) < old:
            shutil.rmtree(leftover, ignore_errors=True)
            removed.append(leftover.name)
    return removed


def _mtime(path: Path) -> float:
    try:
        return path.stat().st_mtime
    except FileNotFoundError:
        return float("-inf")


def node_copy(library, root: Path | None = None) -> Path:
    """The node's folder holding `library` (a cluster.LibraryFiles): written once per node (the first worker there
    writes it into a private folder and renames it into place; a worker that lost the race
    drops its own), and every object's content hash checked before it is used. Held (shared
    lock) for this process's life, touched, and the node's other cached libraries unused for a
    day removed (the rule above CACHE_UNUSED_S)."""
    from corn_drake.assets.content_hash import object_hash
    from corn_drake.assets.manifest import read_manifest

    root = library_cache_root() if root is None else root
    name = library.digest[:24]
    folder = root / name
    root.mkdir(parents=True, exist_ok=True)
    _hold(root, name)  # before looking: from here on no remover takes it
    if not (folder / ".checked").exists():
        arriving = Path(tempfile.mkdtemp(prefix=".arriving-", dir=root))
        try:
            for rel, data in library.files.items():
                path = arriving / rel
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_bytes(data)
            objects = {o.id: o for o in read_manifest(arriving).objects}
            for object_id, expected in library.hashes.items():
                got = object_hash(arriving, objects[object_id])
                if got != expected:
                    raise RuntimeError(f"library object {object_id!r} arrived from "
                                       f"{library.driver_path} with content hash {got[:12]}, "
                                       f"the driver's is {expected[:12]}")
            (arriving / ".checked").write_text("")
            try:
                os.rename(arriving, folder)
            except OSError:  # another worker on this node put it there first
                pass
        finally:
            shutil.rmtree(arriving, ignore_errors=True)
    with contextlib.suppress(OSError):
        os.utime(folder)  # used now
    with contextlib.suppress(OSError):  # cleaning is best effort: never fails a worker's start
        prune_library_cache(root, keep=name)
    return folder
