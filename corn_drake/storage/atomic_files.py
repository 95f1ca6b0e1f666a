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

from corn_drake.errors import InputError, MissingInputError, is_disk_full


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
    except OSError as e:
        # A write that fails (a full disk: ENOSPC) names no file, or the temporary one that
        # is removed below: name the file being written, for the one line the CLI prints.
        if is_disk_full(e) and (e.filename is None or str(e.filename) == str(tmp_path)):
            e.filename = str(path)
        raise
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
