"""Atomic file writes: every data file and checkpoint goes through here (temp file + rename).

Also `read_json`, the reading side for JSON the user hands us, with errors that name the file.
"""

from __future__ import annotations

import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from corn_drake.errors import InputError, MissingInputError


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yields a temporary path in the same folder; renames it onto `path` only on success."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=_temporary_prefix(path), suffix=".tmp", dir=path.parent)
    os.close(fd)
    # mkstemp creates 0600 files; give the result the permissions of a normally created file.
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def _temporary_prefix(path: Path) -> str:
    return f".{path.name}."


def remove_stale_temporaries(path: str | os.PathLike) -> None:
    """Deletes the temporary files that atomic writes of `path` left behind when their process
    was killed (SIGKILL, power loss: no `finally` runs). Only for a file one process writes at a
    time, such as a run's checkpoints (the run folder's lock sees to that)."""
    path = Path(path)
    for stale in path.parent.glob(f"{_temporary_prefix(path)}*.tmp"):
        stale.unlink(missing_ok=True)


def write_json(path: str | os.PathLike, data: Any) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2, sort_keys=False) + "\n")


def write_text(path: str | os.PathLike, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def save_npy(path: str | os.PathLike, array: np.ndarray) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.save(f, array)


def save_npz(path: str | os.PathLike, **arrays: np.ndarray) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)


def read_json(path: str | os.PathLike, what: str) -> Any:
    """The JSON in `path`. A missing, empty, binary or malformed file is an InputError naming
    the file and `what` it should be (e.g. "object library manifest")."""
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"{what} {path}: file not found")
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise InputError(f"{what} {path}: not a UTF-8 text file") from None
    if not text.strip():
        raise InputError(f"{what} {path}: empty file")
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise InputError(f"{what} {path}: not valid JSON ({e})") from None


def ensure_writable(folder: str | os.PathLike, argument: str) -> Path:
    """Proves that `folder` can be made and written, before any long work whose result would go
    there; an InputError names `argument` and the folder otherwise.

    Nothing is left behind: the probe file goes in the nearest folder that already exists (being
    able to write there is what creating the rest of the path needs), and is removed again."""
    from corn_drake.errors import InputError

    folder = Path(folder)
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    try:
        if not existing.is_dir():
            raise NotADirectoryError(f"{existing} is not a folder")
        fd, probe = tempfile.mkstemp(prefix=".write_probe.", dir=existing)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise InputError(f"{argument}: cannot write to {folder} ({e.strerror or e})") from e
    return folder


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

    import torch

    path = Path(path)
    for written in (path, previous_checkpoint(path)):  # a killed earlier save's leftovers
        remove_stale_temporaries(written)
    with atomic_path(path) as tmp:
        torch.save(state, tmp)
        if keep_previous and path.is_file() and _is_complete_torch_file(path):
            with atomic_path(previous_checkpoint(path)) as tmp_previous:
                shutil.copyfile(path, tmp_previous)


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
    """The state saved by save_checkpoint at `path`, or None when there is none to resume.

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
            reason = problems[0] if problems else f"{path}: missing"
            print(f"warning: checkpoint unusable ({reason}); using the previous checkpoint "
                  f"{candidate}", file=sys.stderr)
        return state
    raise InputError("no readable checkpoint: " + "; ".join(problems))
