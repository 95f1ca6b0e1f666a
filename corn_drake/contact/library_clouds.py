"""Reading object surface clouds from an object library's manifest.json (the library's format)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from corn_drake.assets.manifest import read_manifest, require_fields
from corn_drake.errors import InputError


@dataclasses.dataclass
class ObjectCloud:
    id: str
    split: str  # "train" | "unseen"
    radius: float
    points: np.ndarray  # (M, 3) object-frame surface samples


def load_object_clouds(library: str | Path) -> list[ObjectCloud]:
    """All objects of a library with a usable cloud; a library with none is an error."""
    library = Path(library)
    clouds = []
    for entry in read_manifest(library)["objects"]:
        require_fields(library, entry, ("cloud", "radius"))
        path = library / entry["cloud"]
        try:
            cloud = np.load(path)
        except (OSError, ValueError) as e:
            raise InputError(f"object {entry['id']}: cannot read cloud {path} ({e})") from e
        if cloud.ndim != 2 or cloud.shape[1] < 3 or len(cloud) < 512 or not np.isfinite(cloud).all():
            raise InputError(f"object {entry['id']}: cloud {path} must be finite (>=512, 3+), "
                             f"got {cloud.shape}")
        clouds.append(ObjectCloud(entry["id"], entry["split"], float(entry["radius"]),
                                  cloud[:, :3].astype(np.float64)))
    if not clouds:
        raise InputError(f"object library {library} has no usable objects")
    return clouds
