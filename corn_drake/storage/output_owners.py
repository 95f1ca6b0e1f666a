"""Whether an output path may be written by a command: it is new, or it holds an artefact of
the same kind made by the same source (then it is resumed or replaced, as each command does),
or the command is refused in one line naming what is there (issue 63: `evaluate --report
RUN/config.yaml` destroyed a run; a report of one run was replaced by another's). An explicit
--overwrite replaces it (every write is atomic: temporary file + rename).
"""

from __future__ import annotations

import json
from pathlib import Path

from corn_drake.errors import InputError
from corn_drake.storage.weights_card import CARD, read_card


def _describe(path: Path) -> str:
    if path.is_dir():
        return "a folder"
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return "a file that is no JSON report"
    if isinstance(data, dict) and "episodes" in data and "success_rate" in data:
        return f"the report of --run {data.get('run')}"
    return "a JSON file that is no evaluate report"


def check_report_owner(path: Path, run: str, overwrite: bool, flag: str = "--report") -> None:
    """Refuses `path` unless it is new, or an evaluate report of `run` (or a partial one that
    names no run yet), or `overwrite` says to replace whatever is there."""
    if overwrite or not path.exists():
        return
    what = _describe(path)
    if what in (f"the report of --run {run}", "the report of --run None"):
        return
    raise InputError(f"{flag} {path}: holds {what}, which this evaluation of --run {run} would "
                     "replace; give a new path, or --overwrite to replace it")


def check_folder_owner(out: Path, source: str, overwrite: bool, flag: str = "--out") -> None:
    """Refuses weights folder `out` unless it is new or empty, or holds the weights shipped from
    `source` (its card's source_run: shipped again, replaced), or `overwrite` says to replace
    it. What is there is named: another run's shipped weights, an object library, a run."""
    if overwrite or not out.exists():
        return
    if not out.is_dir():
        raise InputError(f"{flag} {out}: is a file; give a folder path")
    entries = list(out.iterdir())
    if not entries:
        return
    if (out / CARD).is_file():
        try:
            shipped_from = (read_card(out) or {}).get("source_run")
        except InputError as e:  # a damaged card: whose weights these are is not known
            raise InputError(f"{flag} {out}: holds shipped weights whose card cannot be read "
                             f"({e}); give a new folder, or --overwrite to replace them with "
                             f"the weights of {source}") from None
        if shipped_from == source:
            return
        what = (f"the weights shipped from {shipped_from}" if shipped_from else
                "shipped weights whose card names no source_run")
    else:
        what = describe_folder(out, sorted(p.name for p in entries))
    raise InputError(f"{flag} {out}: holds {what}; give a new folder, or --overwrite to "
                     f"replace it with the weights of {source}")


def describe_folder(folder: Path, names: list[str]) -> str:
    """What a folder holding `names` is, for a refusal to write there: shipped weights, an
    object library (or dataset), a run, else its first entries. One description for every
    command's output check (this module's and run_folders.guards')."""
    if (folder / CARD).is_file():
        return "shipped weights (card.json)"
    if (folder / "manifest.json").is_file():
        return "an object library or dataset (manifest.json)"
    if (folder / "config.yaml").is_file():
        return "a run (config.yaml)"
    shown = ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
    return f"{len(names)} files of something else ({shown})"


def check_new_file(path: Path | None, overwrite: bool, flag: str = "--out") -> None:
    """Refuses an existing `path` (an artefact a rerun cannot tell from another one: a fitted
    model) unless `overwrite` says to replace it."""
    if path is None or overwrite or not path.exists():
        return
    what = "a folder" if path.is_dir() else f"a file of {path.stat().st_size} bytes"
    raise InputError(f"{flag} {path}: already holds {what}; give a new path, or --overwrite to "
                     "replace it")


def check_gallery_owner(out: Path, run: str, overwrite: bool, flag: str = "--out") -> list[str]:
    """Refuses gallery folder `out` unless it is new or empty, or holds a gallery of `run`
    (gallery.json), or `overwrite` says to replace what is there; returns the files the
    gallery there lists (a new gallery of the same run removes those it does not rewrite, so no
    picture of an earlier call is left beside this one's)."""
    if not out.exists():
        return []
    if not out.is_dir():
        raise InputError(f"{flag} {out}: is a file; give a folder path")
    entries = list(out.iterdir())
    listed: list[str] = []
    index = out / "gallery.json"
    owner = None
    if index.is_file():
        try:
            data = json.loads(index.read_text())
            owner = data.get("run")
            listed = [name for e in data.get("episodes", [])
                      for name in (e.get("image"), e.get("animation")) if name]
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, AttributeError):
            owner = None
    if not entries or overwrite or owner == run:
        return listed
    what = f"the gallery of --run {owner}" if owner else f"{len(entries)} files of something else"
    raise InputError(f"{flag} {out}: holds {what}; give a new folder, or --overwrite to "
                     f"replace it with the gallery of {run}")
