"""An object library's manifest.json: its typed schema, the one reader and the one writer.

LIBRARY/manifest.json holds {"objects": [LibraryObject...], "rejected": [Rejection...],
"split_rule": {...}}; every path in it is relative to LIBRARY and must stay inside it
(read_manifest refuses ".." and absolute paths, library_file symbolic links that point out). It
records what was built, never how long it took (LIBRARY/build_timings.json does), so it is the
same byte for byte whenever the same objects are built (a library written before keeps its
"timings" as fields the schema does not name). Every command that takes --objects reads it
through read_manifest, so a missing or corrupt library is reported the same way (an InputError
naming the file and, for a bad entry, the object and the field), and the library builder writes
it through write_manifest.

Kept apart from assets/library.py so readers (contact data, Ray workers) need not import the
mesh-processing stack the library builder uses.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import types
import typing
from pathlib import Path
from typing import Any

from corn_drake.errors import InputError, MissingInputError
from corn_drake.storage.atomic_files import read_json, write_json

WHAT = "object library manifest"
SPLITS = ("train", "unseen")
# The fields of LibraryObject that name files of the library (relative paths).
FILE_FIELDS = ("hulls", "visual", "cloud", "stable_poses", "bbox_corners", "unit_inertia")


@dataclasses.dataclass
class LibraryObject:
    """One object of the library (one entry of "objects")."""

    id: str
    # "train" | "unseen", assigned over the whole library (assets/splits.py); "" only while an
    # object is being added, never on disk.
    split: str = ""
    family: str = ""
    source: str = ""  # "procedural:<family>:<seed>" or the mesh file, relative to the source folder
    unseen_group: str | None = None  # for unseen objects: "family", "member" or "ingested"
    # What the scene needs (paths relative to the library). A hand-written or test library may
    # leave some out; readers name the fields they need with require().
    radius: float | None = None
    mass: float | None = None
    thin: bool | None = None
    hulls: list[str] | None = None
    visual: str | None = None
    cloud: str | None = None
    stable_poses: str | None = None
    bbox_corners: str | None = None
    unit_inertia: str | None = None
    # How the object was built.
    warnings: list[str] = dataclasses.field(default_factory=list)
    hull_repairs: list[str] = dataclasses.field(default_factory=list)
    num_hulls: int | None = None
    num_stable_poses: int | None = None
    drops: dict | None = None  # stable-pose drop statistics (assets/processing/stable_poses.py)
    stable_pose_kept_fraction: float | None = None
    hull_volume_ratio: float | None = None
    coacd_runs: int | None = None
    # Fields this schema does not name (written by another version): kept and written back.
    extra: dict = dataclasses.field(default_factory=dict)

    def require(self, library: str | Path, fields) -> None:
        """An InputError naming the manifest, this object and the fields it lacks, if any."""
        missing = [f for f in fields if getattr(self, f) is None]
        if missing:
            raise InputError(f"{WHAT} {manifest_path(library)}: object {self.id!r} has no "
                             f"{', '.join(repr(k) for k in missing)}")


@dataclasses.dataclass
class Rejection:
    """An input that did not become an object, and why."""

    source: str
    reason: str


@dataclasses.dataclass
class Manifest:
    objects: list[LibraryObject] = dataclasses.field(default_factory=list)
    rejected: list[Rejection] = dataclasses.field(default_factory=list)
    split_rule: dict | None = None  # the seed and rule the splits were assigned with
    extra: dict = dataclasses.field(default_factory=dict)

    def ids(self, split: str | None = None) -> list[str]:
        """Object ids, in manifest order; only those of `split` when given."""
        return [o.id for o in self.objects if split in (None, o.split)]

    def get(self, library: str | Path, object_id: str) -> LibraryObject:
        for o in self.objects:
            if o.id == object_id:
                return o
        raise InputError(f"object {object_id!r} not in library {library}")


def manifest_path(library: str | Path) -> Path:
    return Path(library) / "manifest.json"


# --- paths and ids that stay inside the library ------------------------------------------------
# A manifest is input: copied from elsewhere, hand-edited, or crafted. A file path in it that is
# absolute or climbs out with "..", or an id that is used as a file name (a gallery's ID.png,
# an evaluation's episode_K_ID.html) and holds a separator, would make readers open, hash or
# hand to Drake files outside the library, and writers write beside the output folder.
def _path_problem(rel: str) -> str | None:
    """Why the manifest path `rel` cannot name a file inside the library (lexically), or None."""
    if "\0" in rel:
        return "holds a NUL character"
    if os.path.isabs(rel):
        return "is absolute"
    # (normpath only when there is a ".." to climb with: a manifest names hundreds of files)
    if ".." in rel and os.path.normpath(rel).split(os.sep)[0] == "..":
        return "leads outside the library"
    return None


def _id_problem(object_id: str) -> str | None:
    if object_id in (".", "..") or any(c in object_id for c in "/\\\0"):
        return "must be a plain name (no '/', '\\', NUL, '.' or '..'): it names files"
    return None


def named_files(obj: LibraryObject) -> list[tuple[str, str]]:
    """(field, relative path) of every file `obj` names, in FILE_FIELDS order; a field holds one
    path or a list (hulls), and a hand-written library may name no file ("")."""
    named = []
    for field in FILE_FIELDS:
        value = getattr(obj, field)
        named += [(field, rel) for rel in ([value] if isinstance(value, str) else value or [])
                  if rel]
    return named


def library_file(library: str | Path, obj: LibraryObject, field: str, rel: str) -> Path:
    """LIBRARY/rel, the file `obj`'s `field` names, after checking that it resolves inside the
    library: read_manifest refused absolute and ".." paths already, and this also follows
    symbolic links (a link inside the library pointing out of it is refused the same way).
    An InputError names the manifest, the object and the path otherwise."""
    library = Path(library)
    path = library / rel
    problem = _path_problem(rel)
    if problem is None:
        try:
            inside = path.resolve().is_relative_to(library.resolve())
        except (OSError, RuntimeError) as e:  # a symlink loop, an unreadable folder
            raise InputError(f"{WHAT} {manifest_path(library)}: object {obj.id!r} {field} "
                             f"path {rel!r} cannot be resolved ({e})") from None
        problem = None if inside else "resolves (through a symbolic link) outside the library"
    if problem:
        raise InputError(f"{WHAT} {manifest_path(library)}: object {obj.id!r} {field} path "
                         f"{rel!r} {problem}")
    return path


# --- typed (de)serialisation ----------------------------------------------------------------
def _matches(value, hint) -> bool:
    """Whether a JSON value fits a field's type (the schema's few kinds: str, int, float, bool,
    list[str], dict, and their `| None`)."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return any(_matches(value, a) for a in args)
    if hint is type(None):
        return value is None
    if origin is list:
        return isinstance(value, list) and all(_matches(v, args[0]) for v in value)
    if hint is dict or origin is dict:
        return isinstance(value, dict)
    if hint is float:  # JSON writes 1.0 as 1
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, hint)


@functools.cache
def _schema(cls) -> tuple[dict[str, Any], tuple[str, ...], bool]:
    """({field: type hint} of the JSON fields, the required ones, whether it keeps unknown
    fields in `extra`) of a record class: resolved
    once per class, not once per object (get_type_hints is slow, and a library has hundreds)."""
    hints = typing.get_type_hints(cls)
    fields = [f for f in dataclasses.fields(cls) if f.name != "extra"]
    required = tuple(f.name for f in fields if f.default is dataclasses.MISSING
                     and f.default_factory is dataclasses.MISSING)
    keeps_extra = any(f.name == "extra" for f in dataclasses.fields(cls))
    return {f.name: hints[f.name] for f in fields}, required, keeps_extra


def _from_json(cls, data, where: str, path: Path):
    """`cls` from a JSON object; a non-object, a missing required field or a value of the
    wrong type raises an InputError naming `where` and the field."""
    if not isinstance(data, dict):
        raise InputError(f"{WHAT} {path}: {where} is not an object")
    hints, required, keeps_extra = _schema(cls)
    values = {}
    for name, hint in hints.items():
        if name not in data:
            continue
        if not _matches(data[name], hint):
            raise InputError(f"{WHAT} {path}: {where} field {name!r} must be "
                             f"{_type_name(hint)}, got {data[name]!r}")
        values[name] = data[name]
    for name in required:
        if name not in values:
            raise InputError(f"{WHAT} {path}: {where} has no {name!r}")
    if keeps_extra:
        values["extra"] = {k: v for k, v in data.items() if k not in hints}
    return cls(**values)


def _type_name(hint) -> str:
    return getattr(hint, "__name__", None) or str(hint).replace("typing.", "")


def _to_json(record) -> dict:
    data = {f.name: getattr(record, f.name) for f in dataclasses.fields(record) if f.name != "extra"}
    return {**data, **getattr(record, "extra", {})}


def manifest_to_json(manifest: Manifest) -> dict:
    data = {"objects": [_to_json(o) for o in manifest.objects],
            "rejected": [_to_json(r) for r in manifest.rejected]}
    if manifest.split_rule is not None:
        data["split_rule"] = manifest.split_rule
    return {**data, **manifest.extra}


def read_manifest(library: str | Path) -> Manifest:
    """The validated manifest of `library`: objects with unique non-empty ids and a split in
    SPLITS, every named field of its type."""
    path = manifest_path(library)
    if not path.is_file():
        raise MissingInputError(f"object library {library}: no manifest.json")
    data = read_json(path, WHAT)
    if not isinstance(data, dict) or not isinstance(data.get("objects"), list):
        raise InputError(f"{WHAT} {path}: expected an object with an 'objects' list")
    if not isinstance(data.get("rejected", []), list):
        raise InputError(f"{WHAT} {path}: 'rejected' must be a list")
    objects = []
    for index, entry in enumerate(data["objects"]):
        where = f"objects[{index}]"
        if not isinstance(entry, dict) or not isinstance(entry.get("id"), str) or not entry["id"]:
            raise InputError(f"{WHAT} {path}: {where} has no 'id' string")
        obj = _from_json(LibraryObject, entry, f"{where} ({entry['id']!r})", path)
        _check_names(obj, path)
        if obj.split not in SPLITS:
            raise InputError(f"{WHAT} {path}: {where} ({obj.id!r}) has split {obj.split!r}, "
                             f"expected one of {SPLITS}")
        objects.append(obj)
    seen = set()
    for obj in objects:
        if obj.id in seen:
            raise InputError(f"{WHAT} {path}: object id {obj.id!r} appears twice")
        seen.add(obj.id)
    rejected = [_from_json(Rejection, r, f"rejected[{i}]", path)
                for i, r in enumerate(data.get("rejected", []))]
    rest = _from_json(Manifest, {k: v for k, v in data.items() if k not in ("objects", "rejected")},
                      "the manifest", path)
    return dataclasses.replace(rest, objects=objects, rejected=rejected)


def _check_names(obj: LibraryObject, path: Path) -> None:
    """An InputError naming the manifest, the object and the value, for an id that is not a
    plain name or a file path that leaves the library on its face (library_file also follows
    symbolic links, when a reader opens the file)."""
    problem = _id_problem(obj.id)
    if problem:
        raise InputError(f"{WHAT} {path}: object id {obj.id!r} {problem}")
    for field, rel in named_files(obj):
        problem = _path_problem(rel)
        if problem:
            raise InputError(f"{WHAT} {path}: object {obj.id!r} {field} path {rel!r} {problem}")


def write_manifest(library: str | Path, manifest: Manifest) -> None:
    """Writes LIBRARY/manifest.json atomically."""
    write_json(manifest_path(library), manifest_to_json(manifest))
