"""Contact-data shards on disk: atomic writes, resumable runs, and a validating reader.

Layout: OUT/<split>/shard_00000.npz (split: train = train objects, val = held-out samples of
train objects, unseen = unseen objects) and OUT/manifest.json with counts, positive fractions
and the seed. Every shard is a function of (seed, split, index) alone.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from corn_drake.errors import InputError, MissingInputError
from corn_drake.storage.atomic_files import read_json, save_npz, write_json

KEYS = {"points": 3, "labels": 2, "hand_pose": 2, "object_pose": 2, "object_id": 1, "scale": 1}


def shard_path(out: Path, split: str, index: int) -> Path:
    return out / split / f"shard_{index:05d}.npz"


def write_shard(path: Path, arrays: dict) -> None:
    save_npz(path, **arrays)


def read_shard(path: str | Path) -> dict[str, np.ndarray]:
    """Loads and checks one shard; any problem is an InputError (a ValueError) naming the file."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        raise InputError(f"contact shard {path}: unreadable ({type(e).__name__}: {e})") from e
    missing = set(KEYS) - set(arrays)
    if missing:
        raise InputError(f"contact shard {path}: missing arrays {sorted(missing)}")
    n = len(arrays["points"])
    if n == 0:
        raise InputError(f"contact shard {path}: empty")
    for key, ndim in KEYS.items():
        if arrays[key].ndim != ndim or len(arrays[key]) != n:
            raise InputError(f"contact shard {path}: {key} has shape {arrays[key].shape}, "
                             f"expected {ndim} dims with {n} samples")
    if arrays["points"].shape[2] != 3 or arrays["labels"].shape != arrays["points"].shape[:2]:
        raise InputError(f"contact shard {path}: points {arrays['points'].shape} and labels "
                         f"{arrays['labels'].shape} do not match")
    for key in ("points", "hand_pose", "object_pose", "scale"):
        if not np.isfinite(arrays[key]).all():
            raise InputError(f"contact shard {path}: {key} has non-finite values")
    return arrays


def shard_is_complete(path: Path, expected: int) -> bool:
    if not path.is_file():
        return False
    try:
        return len(read_shard(path)["points"]) == expected
    except ValueError:
        return False


def list_shards(data: str | Path, split: str) -> list[Path]:
    data = Path(data)
    if not (data / "manifest.json").is_file():
        raise MissingInputError(f"contact data {data}: no manifest.json")
    shards = sorted((data / split).glob("shard_*.npz"))
    if not shards:
        raise InputError(f"contact data {data}: no {split} shards")
    return shards


def load_split(data: str | Path, split: str) -> dict[str, np.ndarray]:
    parts = [read_shard(p) for p in list_shards(data, split)]
    return {k: np.concatenate([p[k] for p in parts]) for k in KEYS}


def write_manifest(out: Path, info: dict) -> None:
    write_json(out / "manifest.json", info)


def read_manifest(data: str | Path) -> dict:
    return read_json(Path(data) / "manifest.json", "contact data manifest")
