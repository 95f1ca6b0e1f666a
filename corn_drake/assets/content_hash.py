"""A library's content hash: what its objects are, not how or when they were built.

Each object's hash covers its identity and the fields the scene and the task draws read (id,
family, source, split, unseen group, mass, radius, thin) and the bytes of every file it names
(hulls, visual mesh, point cloud, stable poses, bounding box, unit inertia). Build records
(timings, drop statistics, warnings) are left out: they differ between runs of the same build.
Floats are hashed at 12 significant digits, so the last bits of a mass computed on another CPU
do not make another library. A library's hash combines its objects' hashes in id order, so a
library built object by object, or with other objects beside them, hashes its common objects
the same (`corn-drake evaluate` compares a library with the one a card was evaluated on, object
by object).

Kept apart from assets/library.py so `evaluate` can check a library without importing the
mesh-processing stack.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from corn_drake.assets.manifest import (LibraryObject, library_file, manifest_path,
                                        named_files, read_manifest)
from corn_drake.errors import InputError, MissingInputError

IDENTITY_FIELDS = ("id", "family", "source", "split", "unseen_group", "thin")
FLOAT_FIELDS = ("mass", "radius")


def object_hash(library: str | Path, obj: LibraryObject) -> str:
    """sha256 (hex) of one object of `library`."""
    library = Path(library)
    h = hashlib.sha256()
    record = {k: getattr(obj, k) for k in IDENTITY_FIELDS}
    record.update({k: None if getattr(obj, k) is None else format(float(getattr(obj, k)), ".12g")
                   for k in FLOAT_FIELDS})
    h.update(json.dumps(record, sort_keys=True).encode())
    for field, rel in named_files(obj):
        path = library_file(library, obj, field, rel)
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            raise MissingInputError(f"object {obj.id!r} of {manifest_path(library)}: {field} "
                                    f"file not found: {path}") from None
        # The name and the length delimit each file, so moving bytes between files changes it.
        h.update(f"\n{field} {rel} {len(data)}\n".encode())
        h.update(data)
    return h.hexdigest()


def object_hashes(library: str | Path, object_ids=None) -> dict[str, str]:
    """{object id: object_hash} for `object_ids` (all of the library's objects when None), in id
    order; an id the library does not hold is an InputError naming it and the manifest."""
    library = Path(library)
    objects = {o.id: o for o in read_manifest(library).objects}
    ids = sorted(objects) if object_ids is None else sorted(object_ids)
    missing = [i for i in ids if i not in objects]
    if missing:
        raise InputError(f"{manifest_path(library)} holds no object {missing[0]!r}")
    return {i: object_hash(library, objects[i]) for i in ids}


def combined_hash(hashes: dict[str, str]) -> str:
    """One hash of {object id: object hash}, independent of the dict's order."""
    text = "".join(f"{i} {hashes[i]}\n" for i in sorted(hashes))
    return hashlib.sha256(text.encode()).hexdigest()


def library_content_hash(library: str | Path, object_ids=None) -> str:
    """The content hash of `library` over `object_ids` (all of its objects when None)."""
    return combined_hash(object_hashes(library, object_ids))
