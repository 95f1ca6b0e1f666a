"""Reading lookahead data (collect.py's episodes_*.npz files) back: the files of several
collect folders as one data dict, and subsets of its states (by index, by object).

A data dict holds per state the features (features_tokens, ...), its outcome parts
(outcome_pose, ...), its episode and its object, and per candidate row the keys of ROW_KEYS
with "state", the index of the row's state.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from corn_drake.errors import InputError, MissingInputError
from corn_drake.rl.primitive.outcome.collect import CHUNK_PATTERN
from corn_drake.rl.primitive.outcome.model import OUTCOME_KEYS, OUTCOME_ROW_KEYS

# The per-candidate arrays (collect.stack_states; the last three only in data collected with
# their outcomes); every other array but "state" has one entry per state.
ROW_KEYS = ("location", "motion", "reward", "pose_after", "still_after", "success_after")
OBJECT_ORDER_SEED = 0  # first_objects' one fixed order of the objects


def load_data(files: list[Path], object_tags: list[str] | None = None) -> dict[str, np.ndarray]:
    """The files' states and rows as one data dict; only the keys every file has (files
    collected before outcomes or objects were stored lack those). `object_tags`: per file, a
    prefix for its object ids (files of libraries whose ids coincide, told apart)."""
    parts = [dict(np.load(p)) for p in files]
    common = set.intersection(*(set(part) for part in parts))
    parts = [{k: v for k, v in part.items() if k in common} for part in parts]
    out, offset = {}, 0
    for i, part in enumerate(parts):  # each file's state indices follow the previous files'
        if object_tags is not None and "object" in part:
            part["object"] = np.array([object_tags[i] + o for o in part["object"]])
        part["state"] = part["state"] + offset
        offset += len(part["features_tokens"])
        for key, value in part.items():
            out.setdefault(key, []).append(value)
    return {key: np.concatenate(value) for key, value in out.items()}


def load_outcome_data(folders: list[Path], tag_folders: bool = True) -> dict[str, np.ndarray]:
    """The collect folders' data with every candidate's outcome, or an InputError naming the
    folder without files or the keys the files lack. With `tag_folders` each object id is
    prefixed by its folder's position ("1:block_000"): libraries of other seeds reuse ids."""
    folders = [Path(f) for f in folders]
    for folder in folders:
        if not folder.is_dir():
            raise MissingInputError(f"--data {folder}: no such folder")
        if not any(folder.glob(CHUNK_PATTERN)):
            raise InputError(f"--data {folder}: no {CHUNK_PATTERN} files (written by "
                             "`corn-drake collect-outcomes`)")
    # One order over every folder's files, by path: the order the shipped fits read them in
    # (the states' order is the fit's batches', so another order gives other weights).
    files = sorted(f for folder in folders for f in folder.glob(CHUNK_PATTERN))
    tags = [f"{folders.index(f.parent)}:" for f in files] if tag_folders else None
    data = load_data(files, tags)
    missing = [k for k in ("object", *OUTCOME_KEYS, *OUTCOME_ROW_KEYS) if k not in data]
    if missing:
        raise InputError(f"--data {' '.join(map(str, folders))}: files without "
                         f"{', '.join(missing)} (collected before they were stored)")
    if len(data["reward"]) == 0:
        raise InputError(f"--data {' '.join(map(str, folders))}: no candidates to fit")
    return data


def select_states(data: dict, states: np.ndarray) -> dict:
    """The data of `states` (state indices), their candidates' rows with them, state indices
    renumbered 0..len-1."""
    states = np.sort(np.asarray(states))
    number = np.full(len(data["features_tokens"]), -1, np.int64)
    number[states] = np.arange(len(states))
    rows = np.flatnonzero(number[data["state"]] >= 0)
    out = {k: v[rows] if k in ROW_KEYS else v[states] for k, v in data.items() if k != "state"}
    out["state"] = number[data["state"][rows]]
    return out


def first_objects(data: dict, count: int) -> dict:
    """The states of the first `count` objects of `data` in one fixed seeded order, so that a
    smaller count's objects are among a larger's (a learning curve over objects), or an
    InputError."""
    objects = sorted(set(data["object"]))
    if not 1 <= count <= len(objects):
        raise InputError(f"--objects {count}: the data have {len(objects)} objects")
    kept = np.random.default_rng(OBJECT_ORDER_SEED).permutation(objects)[:count]
    return select_states(data, np.flatnonzero(np.isin(data["object"], kept)))
