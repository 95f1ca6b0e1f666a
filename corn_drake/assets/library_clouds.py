"""Reading object surface clouds from an object library's manifest.json (the library's format)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from corn_drake.assets.manifest import library_file, read_manifest
from corn_drake.contract import DEFAULT_NUM_POINTS, POSITION_DIM
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
    for obj in read_manifest(library).objects:
        obj.require(library, ("cloud", "radius"))
        path = library_file(library, obj, "cloud", obj.cloud)
        try:
            cloud = np.load(path)
        except (OSError, ValueError) as e:
            raise InputError(f"object {obj.id}: cannot read cloud {path} ({e})") from e
        if (cloud.ndim != 2 or cloud.shape[1] < POSITION_DIM or len(cloud) < DEFAULT_NUM_POINTS
                or not np.isfinite(cloud).all()):
            raise InputError(f"object {obj.id}: cloud {path} must be finite "
                             f"(>={DEFAULT_NUM_POINTS}, 3+), got {cloud.shape}")
        clouds.append(ObjectCloud(obj.id, obj.split, float(obj.radius),
                                  cloud[:, :POSITION_DIM].astype(np.float64)))
    if not clouds:
        raise InputError(f"object library {library} has no usable objects")
    return clouds
