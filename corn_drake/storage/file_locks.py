"""One writer per output file: `locked_output(path, argument)` holds `.NAME.lock` beside `path`
while a command works towards it, so a second command writing the same file refuses at once
instead of both exiting 0 with one result silently overwritten (`evaluate --report`).

The lock is an exclusive `flock` on that file, not the file's existence: the kernel drops a
flock when its process ends, kill -9 included, so a lock file a dead process left behind is
stale by construction and the next command takes it over (no pid guessing, which a reused pid
would fool). The file is removed on release so no `.lock` stays beside a finished report; the
inode check in `_take` closes the race where a second process opened the file just before the
first removed it (it would otherwise hold a lock on a file nobody else can see).
"""

from __future__ import annotations

import fcntl
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from corn_drake.errors import InputError


def lock_path(path: str | os.PathLike) -> Path:
    """The lock file of output `path`: hidden, beside it."""
    path = Path(path)
    return path.with_name(f".{path.name}.lock")


@contextmanager
def locked_output(path: str | os.PathLike, argument: str) -> Iterator[Path]:
    """Holds output `path`'s lock for the block; an InputError naming `argument`, `path` and the
    holder's pid if another process holds it. Folders it had to make for the lock are removed
    again on release while empty (a refused or failed command leaves nothing behind)."""
    path = Path(path)
    made = [p for p in path.absolute().parents if not p.exists()]  # nearest first
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = _take(lock_path(path), argument, path)
    except OSError as e:
        _remove_empty(made)
        raise InputError(f"{argument} {path}: cannot write there ({e.strerror or e})") from e
    except BaseException:
        _remove_empty(made)
        raise
    try:
        yield path
    finally:
        # Unlinked while still held: a process that opens the name afterwards makes a new file,
        # one that opened the old one sees its inode gone (_take) and retries.
        lock_path(path).unlink(missing_ok=True)
        os.close(fd)
        _remove_empty(made)


def _take(lock: Path, argument: str, path: Path) -> int:
    """The descriptor of `lock`, exclusively flocked, the pid written in it."""
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise InputError(f"{argument} {path} is being written by another corn-drake process "
                             f"(pid {holder}); wait for it to end or write another file") from None
        except BaseException:
            os.close(fd)
            raise
        try:
            same = os.fstat(fd).st_ino == os.stat(lock).st_ino
        except FileNotFoundError:
            same = False
        if same:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
            return fd
        os.close(fd)  # its holder released and removed it between our open and flock: again


def _remove_empty(folders: list[Path]) -> None:
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:  # something was written there (the report itself): it stays
            return
