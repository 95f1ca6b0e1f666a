"""Checkpoints (torch.save archives) written atomically, with the previous one kept beside the
latest as prev.pt, and read back with a fallback to it.
"""

from __future__ import annotations

import os
from pathlib import Path

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
