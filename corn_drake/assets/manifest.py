"""Reading an object library's manifest.json: the one reader, so every command that takes
--objects reports a missing or corrupt library the same way (an InputError naming the file).

Kept apart from assets/library.py so readers (contact data, Ray workers) need not import the
mesh-processing stack the library builder uses.
"""

from __future__ import annotations

from pathlib import Path

from corn_drake.errors import InputError, MissingInputError
from corn_drake.io_utils import read_json

WHAT = "object library manifest"


def manifest_path(library: str | Path) -> Path:
    return Path(library) / "manifest.json"


def read_manifest(library: str | Path) -> dict:
    """The validated manifest of `library`: a dict whose "objects" is a list of entries, each
    with a unique string "id" and a string "split"; other fields are checked where used."""
    path = manifest_path(library)
    if not path.is_file():
        raise MissingInputError(f"object library {library}: no manifest.json")
    manifest = read_json(path, WHAT)
    if not isinstance(manifest, dict) or not isinstance(manifest.get("objects"), list):
        raise InputError(f"{WHAT} {path}: expected an object with an 'objects' list")
    if not isinstance(manifest.get("rejected", []), list):
        raise InputError(f"{WHAT} {path}: 'rejected' must be a list")
    seen = set()
    for index, entry in enumerate(manifest["objects"]):
        if not isinstance(entry, dict):
            raise InputError(f"{WHAT} {path}: objects[{index}] is not an object")
        for key in ("id", "split"):
            if not isinstance(entry.get(key), str) or not entry[key]:
                raise InputError(f"{WHAT} {path}: objects[{index}] has no '{key}' string")
        if entry["id"] in seen:
            raise InputError(f"{WHAT} {path}: object id {entry['id']!r} appears twice")
        seen.add(entry["id"])
    return manifest


def require_fields(library: str | Path, entry: dict, keys) -> None:
    """An InputError naming the manifest, the object and the fields it lacks, if any."""
    missing = [k for k in keys if k not in entry]
    if missing:
        raise InputError(f"{WHAT} {manifest_path(library)}: object {entry['id']!r} has no "
                         f"{', '.join(repr(k) for k in missing)}")
