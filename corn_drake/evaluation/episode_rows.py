"""An evaluation's rows file, REPORT.rows.jsonl: one JSON line per finished episode, appended at
once, its first line the header {"settings", "requested": [first, stop)}. Every evaluation
writes one (evaluate's policies and the 6D expert alike, `label` too): a rerun with the same
settings skips the episodes already there, `--episodes-from A --episodes N` plays only k in
[A, N), and merge-reports joins the parts that split runs played (report_merge.py).

Episode k of an evaluation is always its object ids[k % len(ids)], seeded
episode_seed(seed, object, k // len(ids)) (episodes.py), whichever process plays it, so rows
compare and merge row by row.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from corn_drake.errors import InputError
from corn_drake.storage.atomic_files import write_text


def rows_path_of(report_path: Path) -> Path:
    """REPORT.rows.jsonl beside REPORT.json."""
    report_path = Path(report_path)
    return report_path.with_name(report_path.stem + ".rows.jsonl")


def read_rows(path: Path, settings: dict | None, repair: bool = True,
              notes: list | None = None) -> list[dict]:
    """The episode rows of `path` written with `settings` (None: whichever it names; read
    `settings_of` for them). A last line that a kill cut short is dropped (its episode was not
    finished): from the file too with `repair` (a resume), else only said in `notes`."""
    if not path.exists():
        return []
    lines = path.read_text().splitlines()
    records = []
    for i, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            if i != len(lines) - 1:
                raise InputError(f"{path}: line {i + 1} is not a JSON row; the file is damaged"
                                 ) from None
            if repair:
                write_text(path, "".join(f"{json.dumps(r)}\n" for r in records))
            elif notes is not None:
                notes.append(f"{path}: its last line is cut short (a kill mid-write); that "
                             "episode is not counted")
    if not records or "settings" not in records[0]:
        raise InputError(f"{path}: not an evaluation's rows file (its first line names no settings)")
    if settings is not None and records[0]["settings"] != settings:
        change = differing(records[0]["settings"], settings)
        raise InputError(f"{path} holds another evaluation's rows ({change}); choose another "
                         f"--report{AFRESH}")
    return records[1:]


# How a user replaces an evaluation's rows instead of resuming them (evaluate's flag).
AFRESH = " (`evaluate --overwrite` starts it afresh)"


def differing(then: dict, now: dict) -> str:
    """"KEY: A then, B now" for the first setting that differs (what a refusal names)."""
    for key in sorted(set(then) | set(now)):
        if then.get(key) != now.get(key):
            show = lambda v: json.dumps(v)[:80]  # noqa: E731
            return f"{key}: {show(then.get(key))} then, {show(now.get(key))} now"
    return "other settings"


def claim_range(rows_path: Path, settings: dict, episodes: range, rows: list[dict]) -> None:
    """Writes the rows file's header, {"settings", "requested": [first, stop)}: the episodes
    this evaluation was asked for, which merge-reports checks a part against. A resume asks for
    the same range or one holding it (the header then says the larger); another range is
    refused, naming both. A file from before the header said its range gets one when all its
    rows lie in the range asked for."""
    header = {"settings": settings, "requested": [episodes.start, episodes.stop]}
    if not rows_path.exists():
        append_row(rows_path, header)
        return
    lines = rows_path.read_text().splitlines()
    before = json.loads(lines[0]).get("requested")
    had = range(*before) if before else range(min((r["episode"] for r in rows), default=0),
                                              max((r["episode"] for r in rows), default=-1) + 1)
    if had.start < episodes.start or had.stop > episodes.stop:
        if before or rows:
            raise InputError(f"{rows_path} holds the evaluation of episodes {had.start}.."
                             f"{had.stop - 1}; ask for a range holding it (--episodes-from "
                             f"{had.start} --episodes {had.stop}) or give another "
                             f"--report{AFRESH}")
    if before != header["requested"]:
        write_text(rows_path, "\n".join([json.dumps(header), *lines[1:]]) + "\n")


def settings_of(path: Path) -> dict:
    lines = path.read_text().splitlines() if path.is_file() else []
    if not lines:
        raise InputError(f"{path}: no such rows file")
    try:
        return json.loads(lines[0])["settings"]
    except (json.JSONDecodeError, KeyError, TypeError):
        raise InputError(f"{path}: not an evaluation's rows file (its first line names no settings)"
                         ) from None


def append_row(path: Path, record: dict) -> None:
    """One line, flushed to the disk before the next episode starts: a kill loses at most the
    episode being played (read_rows drops a line it cut short)."""
    with open(path, "a") as f:
        f.write(json.dumps(record) + "\n")
        f.flush()
        os.fsync(f.fileno())


def wilson(k: int, n: int, z: float = 1.96) -> list[float] | None:
    """The 95 % Wilson score interval of k successes in n."""
    if n == 0:
        return None
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return [float(centre - half), float(centre + half)]
