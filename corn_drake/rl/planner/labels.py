"""The 6D expert's labels as data: what `evaluate --run planner` wrote to REPORT.labels.jsonl.gz,
read back, and a labelled episode replayed to the very states its labels describe.

A labels file, JSON lines gzipped a line per member (storage/gz_lines.py; files written before
were plain REPORT.labels.jsonl, read the same and gzipped by the next resume): a header line ({"settings": the evaluation's, as its rows file's; "columns":
search.LABEL_COLUMNS}), then one line per episode ({"episode", "object", "seed",
"decisions": [{"chosen", "executed", "labels": [a row per root candidate]}]}). A state is not
stored (512 cloud points and more per decision) but the object's pose there is (`pose`, to a
micrometre): `labelled_states` rebuilds each state's observation by resetting the episode from
its seed (its goal, physics and cloud) and placing the object at that pose. Replaying the
executed primitives instead (`replay`, for files written before poses were) does not land on the
labelled states: the search's simulations from restored snapshots and a fresh episode's step
round differently (measured on the gate A labels: the executed primitive's reward off by a
median 1e-4 at the first decision, 0.15 by the fourth), so it reports that distance.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Iterator

import numpy as np

from corn_drake.errors import InputError

LABELS_SUFFIX = ".labels.jsonl.gz"
PLAIN_LABELS_SUFFIX = ".labels.jsonl"  # the files written before the labels were gzipped


def plain_path_of(path: Path) -> Path:
    """X.labels.jsonl for X.labels.jsonl.gz: where an older writer kept the same labels."""
    return path.with_name(path.name.removesuffix(".gz"))


def gzip_plain_labels(path: Path) -> None:
    """Labels file `path` (X.labels.jsonl.gz) made from its plain predecessor X.labels.jsonl
    where only that exists (a run resumed from before the labels were gzipped; a last line a
    kill cut short is dropped, as a resume would), which is then removed. Both there: refused,
    naming both, as they may hold different episodes."""
    from corn_drake.storage.gz_lines import write_lines

    plain = plain_path_of(path)
    if plain == path or not plain.exists():
        return
    if path.exists():
        raise InputError(f"{plain} and {path} both hold labels of this run; remove the one "
                         "not to resume from")
    lines = plain.read_text().splitlines()
    if lines and not _is_json(lines[-1]):
        lines.pop()
    write_lines(path, [line for line in lines if line.strip()])
    plain.unlink()


def _is_json(line: str) -> bool:
    try:
        json.loads(line)
    except json.JSONDecodeError:
        return False
    return True


def read_labels(path: str | Path) -> tuple[dict, list[str], list[dict]]:
    """(settings, columns, episode records in file order, an episode's last line kept), from a
    gzipped or plain labels file; a last member or line a kill cut short is left out."""
    from corn_drake.storage.gz_lines import read_lines

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such labels file")
    lines = [line for line in read_lines(path)[0] if line.strip()]
    try:
        header = json.loads(lines[0]) if lines else {}
    except json.JSONDecodeError:
        header = {}
    if "settings" not in header or "columns" not in header:
        raise InputError(f"{path}: not a labels file (its first line names no settings and "
                         "columns)")
    episodes: dict[int, dict] = {}
    for line in lines[1:]:
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line a kill cut short: its episode was played again
        episodes[record["episode"]] = record
    return header["settings"], header["columns"], list(episodes.values())


def executed_action(decision: dict, columns: list[str]) -> tuple[dict, tuple | None]:
    """(env action, exact aim or None) of a decision's executed primitive: its `executed`
    record, or for files written before it, the chosen label row (motion to 4 decimals)."""
    if "executed" in decision:
        done = decision["executed"]
        aim = done.get("aim")
        return ({"point": int(done["point"]), "motion": np.asarray(done["motion"], float)},
                None if aim is None else tuple(np.asarray(part, float) for part in aim))
    row = dict(zip(columns, decision["labels"][decision["chosen"]]))
    motion = np.array([row["motion_x"], row["motion_y"], row["motion_z"]], float)
    return {"point": int(row["point"]), "motion": motion}, None


def replay(env, record: dict, columns: list[str]) -> Iterator[tuple[dict, dict, float]]:
    """(observation, decision, |replayed - recorded reward| of the decision's executed
    primitive) for every decision of `record`, on `env` (a PrimitiveEnv of the labelled
    object, the evaluation's env settings), in order."""
    obs, _ = env.reset(seed=record["seed"])
    reward_column = columns.index("reward")
    for decision in record["decisions"]:
        action, aim = executed_action(decision, columns)
        step = env.step(action, aim=aim)
        recorded = decision["labels"][decision["chosen"]][reward_column]
        yield obs, decision, abs(float(step[1]) - recorded)
        obs = step[0]


def labelled_states(env, record: dict, columns: list[str]) -> Iterator[tuple[dict, dict, float]]:
    """(observation, decision, distance) for every decision of `record`: rebuilt from the
    decisions' poses where the file has them (distance 0), else `replay`'s."""
    if not all("pose" in d for d in record["decisions"]):
        yield from replay(env, record, columns)
        return
    env.reset(seed=record["seed"])
    for decision in record["decisions"]:
        env.place_object(decision["pose"])
        yield env.observation(), decision, 0.0
