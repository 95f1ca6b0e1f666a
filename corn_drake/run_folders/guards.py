"""Output folders of the resumable commands (train, pretrain, contact-data, objects).

Two guards keep a folder's contents from one coherent job:

- `lock_folder`: an exclusive `flock` on FOLDER/.lock while a command writes there, so a second
  command into the same folder refuses at once instead of interleaving its files with the
  first's. The kernel drops the lock when the process ends, kill -9 included: no stale lock
  survives a crash, and there is nothing to clean up by hand.
- recorded arguments: a command resuming into a folder must be given the arguments that define
  what is already there. `changed_arguments` compares recorded and requested values;
  `resume_arguments` keeps them in FOLDER/arguments.json for the commands whose outputs do not
  record them otherwise (train and pretrain compare their config.yaml instead).
"""

from __future__ import annotations

import fcntl
import math
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping

from corn_drake.errors import InputError
from corn_drake.storage.atomic_files import read_json, write_json

LOCK_NAME = ".lock"
ARGUMENTS_NAME = "arguments.json"
MADE_BY = "made_by"  # the arguments.json key naming the command that made the folder


@contextmanager
def lock_folder(folder: str | os.PathLike) -> Iterator[Path]:
    """Creates `folder` and holds its lock for the duration of the block (InputError if another
    process holds it, or if the folder cannot be written)."""
    folder = Path(folder)
    existed = folder.is_dir()
    before = set(os.listdir(folder)) if existed else set()
    # The missing folders above it that mkdir(parents=True) makes, nearest first: a refused
    # `train --out runs/x` must not leave an empty runs/ behind either.
    made_parents = []
    for parent in folder.absolute().parents:
        if parent.exists():
            break
        made_parents.append(parent)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(folder / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as e:
        raise InputError(f"{folder}: cannot write there ({e.strerror or e})") from e
    held = False
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
            raise InputError(f"{folder} is in use by another corn-drake process (pid {holder}); "
                             "wait for it to end or write to another folder") from None
        held = True
        # The holder's pid, for the message above (the lock itself is the flock, not this text).
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield folder
    except BaseException:
        _undo_bookkeeping(folder, existed, before, made_parents)
        raise
    finally:
        if held:
            # The pid means something only while the lock is held: emptied on release, a
            # finished folder's files depend on what was made, not on which process made it
            # (two builds of a library are the same byte for byte, .lock included).
            os.ftruncate(fd, 0)
        os.close(fd)  # closing the only descriptor releases the flock


def _undo_bookkeeping(folder: Path, existed: bool, before: set[str],
                      made_parents: list[Path] = ()) -> None:
    """A command that failed before writing any output leaves the folder as it found it: the
    lock file and argument record it added go, and so does the folder if it made it, and the
    parents it made for it (`made_parents`, nearest first) while they are empty. Once real
    output exists, everything stays (the record is what a resume is checked against)."""
    added = set(os.listdir(folder)) - before
    if not added or not added <= {LOCK_NAME, ARGUMENTS_NAME}:
        return
    for name in added:
        (folder / name).unlink(missing_ok=True)
    if existed:
        return
    folder.rmdir()
    for parent in made_parents:
        try:
            parent.rmdir()
        except OSError:  # something else wrote there meanwhile (another command): it stays
            return


def changed_arguments(recorded: Mapping[str, Any], requested: Mapping[str, Any], *,
                      may_grow: Iterable[str] = (), ignore: Iterable[str] = (),
                      name: Callable[[str], str] = str) -> list[str]:
    """One 'NAME: recorded X, requested Y' line per key whose value differs.

    Keys in `ignore` may change freely (they do not define the output); keys in `may_grow` may
    only grow (a run extended to more steps). Keys present on one side only are not compared:
    they come from a version of the code with other fields, and nothing says what they were.
    """
    may_grow, ignore = set(may_grow), set(ignore)
    lines = []
    for key, new in requested.items():
        if key in ignore or key not in recorded:
            continue
        old = recorded[key]
        if key in may_grow and isinstance(old, (int, float)) and isinstance(new, (int, float)):
            if new < old:
                lines.append(f"{name(key)}: recorded {old!r}, requested {new!r} (it may only grow)")
        elif not _same_value(old, new):
            lines.append(f"{name(key)}: recorded {old!r}, requested {new!r}")
    return lines


def _same_value(a: Any, b: Any) -> bool:
    """Equality where NaN equals NaN: a folder recorded with nan and resumed with nan asks for
    nothing new (plain != would call them different and refuse the very command that made it)."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same_value(x, y) for x, y in zip(a, b))
    return a == b


def refuse_changed_arguments(folder: str | os.PathLike, recorded: Mapping[str, Any],
                             requested: Mapping[str, Any], **options) -> None:
    """InputError listing every argument that differs from what `folder` was made with
    (options as for `changed_arguments`)."""
    lines = changed_arguments(recorded, requested, **options)
    if lines:
        raise InputError(f"{folder} was made with other arguments: {'; '.join(lines)}. Repeat "
                         "the recorded arguments to resume it, or write to a new folder")


def read_recorded_arguments(folder: str | os.PathLike) -> dict | None:
    """FOLDER/arguments.json, or None if the folder has none."""
    path = Path(folder) / ARGUMENTS_NAME
    if not path.is_file():
        return None
    recorded = read_json(path, "recorded arguments")
    if not isinstance(recorded, dict):
        raise InputError(f"{path}: expected a JSON object of arguments")
    return recorded


def resume_arguments(folder: str | os.PathLike, requested: Mapping[str, Any], *,
                     made_by: str,
                     may_grow: Iterable[str] = (),
                     legacy: Callable[[Path], Mapping[str, Any] | None] | None = None,
                     holds_own: Callable[[Path], bool] | None = None,
                     renamed: Mapping[str, str] | None = None) -> None:
    """Refuses if `folder` was made with other values of the arguments that define its output
    (`requested`, keyed by option name), or is not `made_by`'s to write (below); otherwise
    records them, and the command, in FOLDER/arguments.json before any work, so even a killed
    job leaves its record.

    `legacy(folder)` recovers the arguments of a folder made before the record was kept (from
    its manifest, say), or returns None when nothing says; `holds_own(folder)` says whether a
    folder without a record holds this command's output all the same (an older library's
    manifest.json). `renamed` maps an option's old spelling, as an older record may hold it, to
    its current one.

    Whose folder (issue 63, ownership): a folder another command recorded, or one holding
    anything without a record that is not this command's own (a run, shipped weights, another
    command's output, files of the user's), is refused in one line naming what is there: a
    command writes only into a new or empty folder or one it made.
    """
    folder = Path(folder)
    recorded = read_recorded_arguments(folder)
    maker = None if recorded is None else recorded.get(MADE_BY) or _legacy_maker(recorded)
    if maker is not None and maker != made_by:
        raise InputError(f"{folder}: holds the output of `corn-drake {maker}`, not of "
                         f"`corn-drake {made_by}`; give another folder")
    if recorded is None and legacy is not None:
        recorded = legacy(folder)
    if recorded is None and not (holds_own is not None and holds_own(folder)):
        from corn_drake.storage.output_owners import describe_folder

        found = sorted(set(os.listdir(folder)) - {LOCK_NAME, ARGUMENTS_NAME})
        if found:
            raise InputError(f"{folder}: holds {describe_folder(folder, found)}, which "
                             f"`corn-drake {made_by}` did not make; it writes only into a new "
                             "or empty folder or one it made: give another folder")
    if recorded is not None:
        recorded = {(renamed or {}).get(k, k): v for k, v in recorded.items()}
        refuse_changed_arguments(folder, recorded, requested, may_grow=may_grow)
    write_json(folder / ARGUMENTS_NAME, {MADE_BY: made_by, **requested})


def _legacy_maker(recorded: Mapping[str, Any]) -> str | None:
    """The command that wrote a record from before records named it, by the arguments only it
    records (objects: --source; contact-data: --num-samples; pretrain: --data, or --objects
    alone for a pretext model's folder)."""
    if "--source" in recorded:
        return "objects"
    if "--num-samples" in recorded:
        return "contact-data"
    if "--data" in recorded or set(recorded) == {"--objects"}:
        return "pretrain"
    return None


def refuse_changed_config(folder: str | os.PathLike, recorded_path: str | os.PathLike, cfg: Any,
                          **options) -> None:
    """Compares a dataclass config with the one a run recorded (its config.yaml), field by field
    (options as for `changed_arguments`, keys 'a.b.c'); nothing to compare for a new run."""
    from corn_drake.config.plumbing.loader import load_config

    recorded_path = Path(recorded_path)
    if not recorded_path.is_file():
        return
    try:
        recorded = load_config(type(cfg), recorded_path)
    except ValueError as e:
        raise InputError(str(e) if isinstance(e, InputError) else
                         f"{recorded_path}: the run's recorded config is unreadable ({e})") from e
    refuse_config_changes(folder, recorded, cfg, **options)


def refuse_config_changes(folder: str | os.PathLike, recorded: Any, requested: Any,
                          **options) -> None:
    """InputError listing every field of `requested` that differs from the `recorded` config of
    `folder` (options as for `changed_arguments`, keys 'a.b.c'). Both go through the YAML dump
    config.yaml is written with, so only real differences count, not float formatting."""
    from corn_drake.config.plumbing.yaml_io import config_fields

    refuse_changed_arguments(folder, config_fields(recorded), config_fields(requested), **options)
