"""Checkpoints (torch.save archives) written atomically, with the previous one kept beside the
latest as prev.pt, and read back with a fallback to it.
"""

from __future__ import annotations

import os
from pathlib import Path

from corn_drake.errors import DiskFullError, is_disk_full
from corn_drake.storage.atomic_files import atomic_path, remove_stale_temporaries


# --- checkpoints -------------------------------------------------------------------------------
# A checkpoint is written atomically and the one it replaces is kept beside it as PREVIOUS_NAME,
# so a latest checkpoint that is unreadable anyway (a full disk, a file damaged after the fact)
# costs one checkpoint interval instead of the whole run.
PREVIOUS_NAME = "prev.pt"


def previous_checkpoint(path: str | os.PathLike) -> Path:
    return Path(path).with_name(PREVIOUS_NAME)


def _is_complete_torch_file(path: Path) -> bool:
    """torch.save writes a zip archive: a truncated or garbage file fails the zip checks, without
    unpickling anything."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as archive:
            return archive.testzip() is None
    except (OSError, zipfile.BadZipFile):
        return False


def save_checkpoint(path: str | os.PathLike, state: dict, keep_previous: bool = True) -> None:
    """torch.save(state) to `path` atomically; the checkpoint it replaces becomes prev.pt
    (not with keep_previous=False: a kept snapshot beside last.pt must not take its prev.pt).

    `path` is a complete file at every instant: the old one is copied to prev.pt (itself an
    atomic write) before the new one is renamed over it. An old file that is not a complete
    checkpoint is not rotated, so it never overwrites a good prev.pt.
    """
    import shutil

    path = Path(path)
    for written in (path, previous_checkpoint(path)):  # a killed earlier save's leftovers
        remove_stale_temporaries(written)
    rotate = keep_previous and path.is_file() and _is_complete_torch_file(path)
    written = 0  # bytes of the new checkpoint on disk (for the message of a full disk)
    try:
        with atomic_path(path) as tmp:
            try:
                save_torch(tmp, state)
            finally:  # all of it, or as far as it got
                written = tmp.stat().st_size if tmp.exists() else 0
            if rotate:
                with atomic_path(previous_checkpoint(path)) as tmp_previous:
                    shutil.copyfile(path, tmp_previous)
    except OSError as e:
        # atomic_path removed the partial files and left `path` and prev.pt as they were, so a
        # full disk costs this checkpoint only: say so in one line, not a traceback.
        if is_disk_full(e):
            raise DiskFullError(disk_full_message(path, keep_previous, rotate, written)) from e
        raise


def save_torch(path: str | os.PathLike, state) -> None:
    """torch.save(state) into the file `path`, a failed write raising the OSError that says why
    (ENOSPC: a full disk). Given a path, torch's C++ writer turns it into a RuntimeError ("file
    write failed"); given a Python file, it writes through its write(), but on the way out
    writes the zip's end anyway and raises a RuntimeError of its own ("unexpected pos"), the
    OSError only its __context__. So the first OSError of a write is kept and raised instead.
    (Through a file object the archive is also named "archive", not after the temporary file.)"""
    import torch

    with open(path, "wb") as f:
        sink = _WriteErrorKept(f)
        try:
            torch.save(state, sink)
        except Exception:
            if sink.error is not None:
                raise sink.error from None
            raise


class _WriteErrorKept:
    """A binary file for torch.save that keeps the first OSError its write() raised."""

    def __init__(self, file):
        self.file, self.error = file, None

    def write(self, data) -> int:
        try:
            return self.file.write(data)
        except OSError as e:
            self.error = self.error or e
            raise

    def flush(self) -> None:
        self.file.flush()


def disk_full_message(path: Path, keep_previous: bool, rotated: bool, written: int = 0) -> str:
    """One line for a checkpoint `path` that could not be written for want of space: what was
    kept, and how much to free in which folder. The bytes are an estimate: the new checkpoint
    is about as large as the one already there (or at least the `written` bytes it reached),
    rotating copies the old one to prev.pt too, less what is free now."""
    import shutil

    previous = previous_checkpoint(path)
    kept = [p for p in ((path, previous) if keep_previous else (path,)) if p.is_file()]
    said = (f"the previous checkpoint{'s' if len(kept) > 1 else ''} "
            f"{' and '.join(map(str, kept))} {'are' if len(kept) > 1 else 'is'} kept unchanged"
            if kept else "no earlier checkpoint was there to lose")
    try:
        free = shutil.disk_usage(path.parent).free
    except OSError:
        free = None
    old = next((p.stat().st_size for p in (path, previous) if p.is_file()), 0)
    need = max(written, old) + (old if rotated else 0) - (free or 0)
    amount = f" about {_size(need)} more" if need > 0 and (old or written) else " space"
    now = f" ({_size(free)} free now)" if free is not None else ""
    return (f"no space left on the device to write checkpoint {path}: {said}; free{amount} in "
            f"{path.parent}{now}, then run the same command again to resume")


def _size(num_bytes: float) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB"):
        if num_bytes < 1024 or unit == "GiB":
            return f"{num_bytes:.0f} {unit}" if unit == "bytes" else f"{num_bytes:.1f} {unit}"
        num_bytes /= 1024


def _read_checkpoint(path: Path, required: tuple[str, ...]) -> dict:
    """The state in `path`; any reason it cannot be used is a ValueError saying why."""
    import torch

    try:
        state = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as e:  # torch and pickle raise many types for a damaged file
        first_line = (str(e).splitlines() or [""])[0][:200]
        raise ValueError(f"{type(e).__name__}: {first_line}") from e
    if not isinstance(state, dict):
        raise ValueError(f"holds a {type(state).__name__}, not a checkpoint dict")
    missing = [k for k in required if k not in state]
    if missing:
        raise ValueError(f"missing {missing}")
    return state


def load_checkpoint(path: str | os.PathLike, required: tuple[str, ...] = (),
                    fallback: bool = True) -> dict | None:
    """The state saved by save_checkpoint at `path` (load_checkpoint_and_file's state)."""
    loaded = load_checkpoint_and_file(path, required, fallback)
    return None if loaded is None else loaded[0]


def load_checkpoint_and_file(path: str | os.PathLike, required: tuple[str, ...] = (),
                             fallback: bool = True) -> tuple[dict, Path] | None:
    """(the state saved by save_checkpoint at `path`, the file it was read from: `path`, or
    prev.pt beside it after a fallback, so a report can say which it measured), or None when
    there is none to resume.

    An unreadable latest checkpoint falls back to prev.pt with a warning on stderr (not with
    fallback=False: a named snapshot is that step or nothing); when no checkpoint there can be
    read, an InputError names the files and why.
    """
    import sys

    from corn_drake.errors import InputError

    path = Path(path)
    others = (previous_checkpoint(path),) if fallback else ()
    candidates = [p for p in (path, *others) if p.is_file()]
    if not candidates:
        return None
    problems = []
    for candidate in candidates:
        try:
            state = _read_checkpoint(candidate, required)
        except ValueError as e:
            problems.append(f"{candidate}: {e}")
            continue
        if candidate != path:
            reason = " ".join((problems[0] if problems else f"{path}: missing").split())
            print(f"warning: checkpoint unusable ({reason}); using the previous checkpoint "
                  f"{candidate}", file=sys.stderr)
        return state, candidate
    raise InputError("no readable checkpoint: " + "; ".join(problems))
