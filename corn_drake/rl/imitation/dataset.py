"""The expert's labels as training arrays: every labelled state rebuilt (rl/planner/labels.py)
and each of its candidates turned into the chooser's features (features.py).

The labels are the data (models/labels/TASK/*.labels.jsonl.gz, written by `corn-drake label`, or an
`evaluate --run planner` report's); a state's observation is rebuilt from its episode's seed and
the object's recorded pose (rl/planner/labels.labelled_states; older files: replayed, which drifts)
on the objects of the library the labels name (its content hash checked when the file records
one). Each episode's arrays are kept in a cache folder under a hash of its record and its file's
settings (gzipped or not, the same labels find the same arrays), so a second fit reads them at
once and a grown labels file costs only its new episodes.

Arrays (one row per candidate): "x" (R, F) the features with the token last, "reward" (R,), "value"
(R,) NaN outside the beam, "state" (R,) the state's index; per state (a searched state, then the
states its beam's candidates reached, search.child_labels): "chosen" (S,) the expert's choice as
a row index (-1 at a reached state, where the expert chose nothing), "object" (S,), "drift"
(S,) |replayed - recorded reward| of the executed primitive where a state was replayed (0 where
it was rebuilt from its pose).
"""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import numpy as np

from corn_drake.errors import InputError

# Bump when what a row or state holds changes (2: reached states; 3: cached by episode).
CACHE_VERSION = 3
KEY_CHARS = 20  # of an episode's sha256 (episode_key), naming its cached arrays


def label_files(paths: list[Path]) -> list[Path]:
    """The labels files `paths` name (files, or folders read for *.labels.jsonl.gz and the
    plain *.labels.jsonl older runs wrote), sorted within each folder, or an error naming the
    path with none."""
    from corn_drake.rl.planner.labels import LABELS_SUFFIX, PLAIN_LABELS_SUFFIX

    out = []
    for path in map(Path, paths):
        if path.is_dir():
            found = sorted([*path.glob(f"*{LABELS_SUFFIX}"),
                            *path.glob(f"*{PLAIN_LABELS_SUFFIX}")])
            both = [p for p in found if p.suffix != ".gz" and p.with_name(p.name + ".gz")
                    in found]
            if both:  # one round's labels twice: a fit would count them twice
                raise InputError(f"--labels {path}: {both[0].name} and its gzipped copy are "
                                 "both there; keep one")
            if not found:
                raise InputError(f"--labels {path}: no *{LABELS_SUFFIX} files (written by "
                                 "`corn-drake label`)")
            out.extend(found)
        elif path.is_file():
            out.append(path)
        else:
            raise InputError(f"--labels {path}: no such file or folder")
    return out


def file_arrays(path: Path, library: Path, cache: Path | None, progress: bool = False) -> dict:
    """The arrays of labels file `path` (its objects read from `library`): each episode's from
    `cache` when there, else rebuilt and cached. Cached by episode, not by file, because a
    labels file grows an episode at a time (a labelling run in progress, a resumed round): a
    fit reads what earlier fits rebuilt and rebuilds only the episodes added since."""
    from tqdm import tqdm

    from corn_drake.rl.planner.labels import read_labels

    settings, columns, records = read_labels(path)
    _check_library(path, settings, library)
    context = None  # the env config and proposing run, loaded at the first episode to rebuild
    parts = []
    bar = tqdm(records, desc=f"states of {path.name}", unit="episode", disable=not progress)
    for record in bar:
        key = episode_key(settings, columns, record)
        if cache is not None and (cache / key).is_file():
            with np.load(cache / key) as stored:
                parts.append(dict(stored))
            continue
        context = context or _replay_context(path, settings)
        arrays = episode_arrays(path, context, columns, record, library)
        if arrays is None:
            continue
        if cache is not None:
            from corn_drake.storage.atomic_files import save_npz

            cache.mkdir(parents=True, exist_ok=True)
            save_npz(cache / key, **arrays)
        parts.append(arrays)
    if not parts:
        raise InputError(f"{path}: no labelled states")
    return join_arrays(parts)


def episode_key(settings: dict, columns: list, record: dict) -> str:
    """The cache file of one episode's arrays: a hash of everything they are made from (the
    labelling's settings, its columns, the episode's record)."""
    import json

    text = json.dumps([settings, columns, record], sort_keys=True)
    return f"{hashlib.sha256(text.encode()).hexdigest()[:KEY_CHARS]}_v{CACHE_VERSION}.npz"


def join_arrays(parts: list[dict]) -> dict:
    """One set of arrays from several (episodes, files): state and row indices offset."""
    out: dict[str, list] = {}
    rows = states = 0
    for arrays in parts:
        arrays = dict(arrays)
        arrays["state"] = arrays["state"] + states
        arrays["chosen"] = np.where(arrays["chosen"] >= 0, arrays["chosen"] + rows, -1)
        rows += len(arrays["reward"])
        states += len(arrays["chosen"])
        for k, v in arrays.items():
            out.setdefault(k, []).append(v)
    return {k: np.concatenate(v) for k, v in out.items()}


def _check_library(path: Path, settings: dict, library: Path) -> None:
    from corn_drake.assets.content_hash import library_content_hash
    from corn_drake.assets.library import list_objects

    missing = sorted(set(settings["objects"]) - set(list_objects(library)))
    if missing:
        raise InputError(f"{path}: labels of objects {', '.join(missing[:3])} that --objects "
                         f"{library} does not hold")
    recorded = settings.get("library_content_hash")
    if recorded and recorded != library_content_hash(library, settings["objects"]):
        raise InputError(f"{path}: labelled on other objects than --objects {library} holds "
                         "(the library's content hash differs); replaying them would describe "
                         "other states")


def state_arrays(path: Path, library: Path, progress: bool = False) -> dict:
    """Every state of labels file `path` rebuilt on `library`'s objects, as arrays (no cache)."""
    return file_arrays(path, library, None, progress)


def _replay_context(path: Path, settings: dict) -> dict:
    """What rebuilding a labels file's states needs: its env config, executor settings, the
    proposing run's agent and its outcome model (whose predicted reward is a feature)."""
    from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
    from corn_drake.config.primitive import PrimitiveConfig
    from corn_drake.rl.planner.sources import load_policy

    if "policy" not in settings["planner"]["sources"]:
        raise InputError(f"{path}: labels of a search without the policy source (the chooser "
                         "learns among a primitive run's candidates)")
    primitive = PrimitiveConfig(**settings["primitive"])
    cfg = dataclasses.replace(load_primitive_env_config(settings["task"]),
                              seed=settings["seed"])
    agent = load_policy(settings["planner"]["policy"], primitive, cfg.task)
    # A learned chooser's run proposes through the outcome model inside it.
    outcome = getattr(agent.outcome_chooser, "inner", agent.outcome_chooser)
    if outcome is None:
        raise InputError(f"{path}: its proposing run {settings['planner']['policy']} has no "
                         "outcome model, whose predicted reward the chooser reads")
    return {"cfg": cfg, "primitive": primitive, "agent": agent, "outcome": outcome}


def episode_arrays(path: Path, context: dict, columns: list, record: dict,
                   library: Path) -> dict | None:
    """The arrays of one episode's labelled states: each searched state, then the states its
    beam's candidates reached (their rewards known, their values not: `chosen` -1)."""
    from corn_drake.assets.library import load_object_spec
    from corn_drake.rl.envs.primitive_env import PrimitiveEnv
    from corn_drake.rl.primitive.value_chooser.features import candidate_features
    from corn_drake.rl.planner.labels import labelled_states
    from corn_drake.rl.primitive.outcome.chooser import candidates_of

    cfg, primitive, agent = context["cfg"], context["primitive"], context["agent"]
    col = {name: i for i, name in enumerate(columns)}
    xs, rewards, values, states, chosen, objects, drift = [], [], [], [], [], [], []
    row_count = 0
    env = PrimitiveEnv(cfg, primitive, load_object_spec(library, record["object"]))
    for obs, decision, off in labelled_states(env, record, columns):
        states_here = [(obs, decision["labels"], int(decision["chosen"]), off)]
        for child in decision.get("children", []):
            env.place_object(child["pose"])
            states_here.append((env.observation(), child["labels"], -1, 0.0))
        for state_obs, labels, choice, distance in states_here:
            if any(r[col["source"]] != "policy" for r in labels):
                raise InputError(f"{path}: episode {record['episode']} has candidates of "
                                 "other sources than the policy")
            rows = [(int(r[col["location"]]), int(r[col["point"]]),
                     np.array([r[col["motion_x"]], r[col["motion_y"]], r[col["motion_z"]]]))
                    for r in labels]
            features, _ = agent.features(state_obs)
            c = candidates_of(agent, state_obs, features, rows)
            predicted = context["outcome"].scores(c, cfg.task, primitive.progress_reward)
            xs.append(candidate_features(c, predicted, tokens=True).numpy())
            rewards.append([r[col["reward"]] for r in labels])
            values.append([np.nan if r[col["value"]] is None else r[col["value"]]
                           for r in labels])
            states.append(np.full(len(labels), len(chosen)))
            chosen.append(row_count + choice if choice >= 0 else -1)
            objects.append(record["object"])
            drift.append(distance)
            row_count += len(labels)
    if not chosen:  # an episode with no decision: no rows
        return None
    return {"x": np.concatenate(xs).astype(np.float32),
            "reward": np.concatenate(rewards).astype(np.float32),
            "value": np.concatenate(values).astype(np.float32),
            "state": np.concatenate(states).astype(np.int64),
            "chosen": np.asarray(chosen, np.int64), "object": np.asarray(objects),
            "drift": np.asarray(drift, np.float32)}


def load_label_arrays(paths: list[Path], library: Path, cache: Path | None,
                      progress: bool = False) -> dict:
    """The arrays of every labels file `paths` name, as one (state and row indices offset)."""
    return join_arrays([file_arrays(path, library, cache, progress)
                        for path in label_files(paths)])
