"""Reading object surface clouds from an object library's manifest.json (the library's format)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np


@dataclasses.dataclass
class ObjectCloud:
    id: str
    split: str  # "train" | "unseen"
    radius: float
    points: np.ndarray  # (M, 3) object-frame surface samples


def load_object_clouds(library: str | Path) -> list[ObjectCloud]:
    """All objects of a library with a usable cloud; a library with none is an error."""
    library = Path(library)
    manifest_path = library / "manifest.json"
    if not manifest_path.is_file():
        raise FileNotFoundError(f"object library {library}: no manifest.json")
    try:
        manifest = json.loads(manifest_path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"object library {manifest_path}: not valid JSON ({e})") from e
    clouds = []
    for entry in manifest.get("objects", []):
        path = library / entry["cloud"]
        try:
            cloud = np.load(path)
        except (OSError, ValueError) as e:
            raise ValueError(f"object {entry['id']}: cannot read cloud {path} ({e})") from e
        if cloud.ndim != 2 or cloud.shape[1] < 3 or len(cloud) < 512 or not np.isfinite(cloud).all():
            raise ValueError(f"object {entry['id']}: cloud {path} must be finite (>=512, 3+), "
                             f"got {cloud.shape}")
        clouds.append(ObjectCloud(entry["id"], entry["split"], float(entry["radius"]),
                                  cloud[:, :3].astype(np.float64)))
    if not clouds:
        raise ValueError(f"object library {library} has no usable objects")
    return clouds
