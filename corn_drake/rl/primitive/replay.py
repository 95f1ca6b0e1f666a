"""A ring-buffer replay of contact-primitive transitions for the off-policy (TD3) learner.

One transition is (features s, chosen location, motion, reward, done, next features s'), where a
features dict holds one state's `tokens` (L, D), `local` (L, K) and `global` (G,) arrays (see
corn_drake.nn.primitive_heads). Storage is plain numpy, allocated on the first add from that
transition's shapes, so the buffer needs no dims up front and every later add must match them.

Memory: tokens dominate, so they are kept as float16 (they are a frozen encoder's outputs, whose
precision beyond ~3 digits the heads cannot use); everything else is float32, the location
int64. Bytes per transition = 2 x (2·L·D + 4·L·K + 4·G) + 8 + 4·motion_dim + 4 + 4; with the
usual L=16, D=128, K=9, G=146 and a 3-D motion that is 2 x 5256 + 28 = 10,540 bytes (about
10.3 KiB, ~1.05 GB for 100k transitions; float32 tokens would make it 18.3 KiB).

`save` writes only the filled part plus the ring position (atomically), and `load` restores the
exact storage order, so sampling with the same generator after a resume draws the same batches.
"""

from __future__ import annotations

import os
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import torch

from corn_drake.errors import InputError, MissingInputError
from corn_drake.storage.atomic_files import save_npz

_STATES = ("features", "next_features")
# Stored half precision: the bulk of every transition (see the module docstring).
_HALF_KEYS = frozenset({"tokens"})
_FORMAT_VERSION = 1


def _dtype_for(key: str) -> np.dtype:
    return np.dtype(np.float16 if key in _HALF_KEYS else np.float32)


class ReplayBuffer:
    """Fixed-capacity FIFO of transitions; the oldest is overwritten once full."""

    def __init__(self, capacity: int):
        if not isinstance(capacity, (int, np.integer)) or isinstance(capacity, bool) \
                or capacity < 1:
            raise ValueError(f"capacity: expected an int >= 1, got {capacity!r}")
        self._capacity = int(capacity)
        self._size = 0
        self._pos = 0  # where the next transition goes
        # name -> (capacity, ...) array; names are "features/<key>", "next_features/<key>",
        # "location", "motion", "reward", "done". Empty until the first add fixes the shapes.
        self._store: dict[str, np.ndarray] = {}
        self._feature_keys: tuple[str, ...] = ()

    @property
    def capacity(self) -> int:
        return self._capacity

    def __len__(self) -> int:
        return self._size

    # ----------------------------------------------------------------------------------- adding

    def add(self, features: Mapping[str, np.ndarray], location: int, motion: np.ndarray,
            reward: float, done: bool, next_features: Mapping[str, np.ndarray]) -> None:
        """Stores one transition; `features`/`next_features` are unbatched (tokens (L, D), ...)."""
        self.add_batch(
            {k: np.asarray(v)[None] for k, v in _as_mapping(features, "features").items()},
            np.asarray([location]), np.asarray(motion)[None], np.asarray([reward]),
            np.asarray([done]),
            {k: np.asarray(v)[None] for k, v in
             _as_mapping(next_features, "next_features").items()})

    def add_batch(self, features: Mapping[str, np.ndarray], locations: np.ndarray,
                  motions: np.ndarray, rewards: np.ndarray, dones: np.ndarray,
                  next_features: Mapping[str, np.ndarray]) -> None:
        """Stores N transitions at once; every array has a leading N axis (e.g. from N envs)."""
        columns = self._columns(features, locations, motions, rewards, dones, next_features)
        n = len(columns["location"])
        if n == 0:
            return
        if self._store:
            self._check_against_store(columns)
        locations_count = columns["features/tokens"].shape[1]
        loc = columns["location"]
        if loc.min() < 0 or loc.max() >= locations_count:
            raise ValueError(f"location: expected indices in [0, {locations_count}), got "
                             f"{loc.min()}..{loc.max()}")
        if not self._store:
            self._allocate(columns)
        # Only the newest `capacity` of a batch larger than the buffer can survive.
        skip = max(0, n - self._capacity)
        start = (self._pos + skip) % self._capacity
        rows = (start + np.arange(n - skip)) % self._capacity
        for name, column in columns.items():
            self._store[name][rows] = column[skip:]
        self._pos = (self._pos + n) % self._capacity
        self._size = min(self._size + n, self._capacity)

    def _columns(self, features, locations, motions, rewards, dones,
                 next_features) -> dict[str, np.ndarray]:
        columns: dict[str, np.ndarray] = {}
        for state, value in (("features", features), ("next_features", next_features)):
            value = _as_mapping(value, state)
            keys = tuple(sorted(value))
            if "tokens" not in keys:
                raise ValueError(f"{state}: missing key 'tokens'")
            if self._feature_keys and keys != self._feature_keys:
                raise ValueError(f"{state}: keys {list(keys)} differ from the first "
                                 f"transition's {list(self._feature_keys)}")
            if not self._feature_keys and state == "next_features" and \
                    keys != tuple(sorted(features)):
                raise ValueError(f"next_features: keys {list(keys)} differ from features' "
                                 f"{sorted(features)}")
            for key in keys:
                columns[f"{state}/{key}"] = np.asarray(value[key])
        columns["location"] = np.asarray(locations)
        columns["motion"] = np.asarray(motions, dtype=np.float32)
        columns["reward"] = np.asarray(rewards, dtype=np.float32)
        columns["done"] = np.asarray(dones, dtype=np.float32)
        if columns["location"].dtype.kind not in "iu":
            raise ValueError(f"location: expected integers, got dtype {columns['location'].dtype}")
        columns["location"] = columns["location"].astype(np.int64)
        for name, column in columns.items():
            if column.ndim == 0:
                raise ValueError(f"{name}: expected a leading batch axis, got a scalar")
        n = len(columns["location"])
        for name, column in columns.items():
            if len(column) != n:
                raise ValueError(f"{name}: {len(column)} rows, but location has {n}")
            if column.dtype.kind == "f" and not np.isfinite(column).all():
                raise ValueError(f"{name}: holds NaN or infinite values")
        if columns["location"].ndim != 1 or columns["reward"].ndim != 1 \
                or columns["done"].ndim != 1:
            raise ValueError("location/reward/done: expected one scalar per transition")
        if columns["motion"].ndim != 2:
            raise ValueError(f"motion: expected a 1-D motion per transition, got shape "
                             f"{columns['motion'].shape[1:]}")
        for state in _STATES:
            shape = columns[f"{state}/tokens"].shape[1:]
            if len(shape) != 2:
                raise ValueError(f"{state}['tokens']: expected (L, D) per transition, got "
                                 f"{shape}")
        return columns

    def _allocate(self, columns: Mapping[str, np.ndarray]) -> None:
        for name, column in columns.items():
            if name.startswith(_STATES):
                dtype = _dtype_for(name.split("/", 1)[1])
            else:
                dtype = column.dtype
            # np.zeros: the OS hands out pages lazily, so an unfilled buffer costs little.
            self._store[name] = np.zeros((self._capacity, *column.shape[1:]), dtype=dtype)
        self._feature_keys = tuple(sorted(name.split("/", 1)[1] for name in columns
                                          if name.startswith("features/")))

    def _check_against_store(self, columns: Mapping[str, np.ndarray]) -> None:
        for name, column in columns.items():
            want = self._store[name].shape[1:]
            if column.shape[1:] != want:
                raise ValueError(f"{_display(name)}: shape {column.shape[1:]} per transition "
                                 f"differs from the first transition's {want}")

    # --------------------------------------------------------------------------------- sampling

    def sample(self, batch_size: int, rng: np.random.Generator,
               device: str | torch.device = "cpu") -> dict:
        """A uniform batch (with replacement) as float32 tensors (location: int64)."""
        if not isinstance(batch_size, (int, np.integer)) or batch_size < 1:
            raise ValueError(f"batch_size: expected an int >= 1, got {batch_size!r}")
        if self._size == 0:
            raise ValueError("sample: the replay buffer is empty")
        rows = rng.integers(0, self._size, size=int(batch_size))

        def tensor(name: str, dtype=torch.float32) -> torch.Tensor:
            return torch.from_numpy(self._store[name][rows]).to(device=device, dtype=dtype)

        batch: dict = {state: {key: tensor(f"{state}/{key}") for key in self._feature_keys}
                       for state in _STATES}
        batch["location"] = tensor("location", torch.long)
        batch["motion"] = tensor("motion")
        batch["reward"] = tensor("reward")
        batch["done"] = tensor("done")
        return batch

    # ---------------------------------------------------------------------------- save and load

    def save(self, path: str | os.PathLike) -> None:
        """Writes the filled part, the ring position and the capacity to `path` (.npz), atomically
        (a reader never sees a half-written file; a crash leaves the previous one)."""
        arrays = {name: array[:self._size] for name, array in self._store.items()}
        save_npz(path, **arrays,
                 meta=np.asarray([_FORMAT_VERSION, self._capacity, self._size, self._pos],
                                 dtype=np.int64))

    @classmethod
    def load(cls, path: str | os.PathLike, capacity: int | None = None) -> ReplayBuffer:
        """The buffer saved at `path`. With the saved capacity (the default) the storage order
        and ring position come back exactly; a different capacity (at least the saved size)
        gets the transitions oldest-first, the next add going after the newest."""
        path = Path(path)
        if not path.is_file():
            raise MissingInputError(f"replay buffer {path}: file not found")
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {name: data[name] for name in data.files}
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
            raise InputError(f"replay buffer {path}: not a readable .npz file ({e})") from None
        meta = arrays.pop("meta", None)
        if meta is None or meta.shape != (4,) or int(meta[0]) != _FORMAT_VERSION:
            raise InputError(f"replay buffer {path}: missing or unknown format header")
        saved_capacity, size, pos = (int(v) for v in meta[1:])
        if capacity is None:
            capacity = saved_capacity
        buffer = cls(capacity)
        if size > capacity:
            raise ValueError(f"capacity: {capacity} is smaller than the {size} transitions saved "
                             f"in {path}")
        if size == 0:
            return buffer
        for name, array in arrays.items():
            if len(array) != size:
                raise InputError(f"replay buffer {path}: {name} has {len(array)} rows, "
                                 f"expected {size}")
        if capacity != saved_capacity:
            # Unroll the ring so the oldest transition comes first.
            oldest = pos if size == saved_capacity else 0
            arrays = {name: np.roll(array, -oldest, axis=0) for name, array in arrays.items()}
            pos = size % capacity
        buffer._allocate(arrays)
        for name, array in arrays.items():
            buffer._store[name][:size] = array
        buffer._size, buffer._pos = size, pos
        return buffer


def _as_mapping(value, name: str) -> Mapping[str, np.ndarray]:
    if not isinstance(value, Mapping):
        raise ValueError(f"{name}: expected a dict of arrays, got {type(value).__name__}")
    return value


def _display(name: str) -> str:
    """'features/tokens' -> "features['tokens']", the way a caller wrote it."""
    if "/" in name:
        state, key = name.split("/", 1)
        return f"{state}[{key!r}]"
    return name
