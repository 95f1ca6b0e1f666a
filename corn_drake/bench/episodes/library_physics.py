"""`bench sim --objects LIB [LIB ...]`: bare-physics policy steps/s of every object of libraries.

What an object costs the simulator depends on its collision geometry, mostly its number of
convex hulls (a resting 16-hull mug has ~10 hydroelastic contacts with the table). For each
object of the chosen split, the bare plant of the teacher scene holding it replays the torques of
the same random-action plans recorded on its own env (bench/bare_physics.py). With two
or more libraries of the same objects (e.g. built with another hull budget, `objects
--max-hulls`), each object is measured in every library in turn, alternating, so load from
other processes falls on all of them alike; per object `ratio` is its rate in each library over
the first's, and the summary gives the mean rates and the geometric mean of the ratios.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path

from corn_drake.errors import InputError


def object_config(base_cfg, library: str, object_id: str):
    """`base_cfg` (a TeacherDiagramConfig) holding `object_id` of `library`."""
    cfg = copy.deepcopy(base_cfg)
    obj = cfg.scene.object
    obj.kind, obj.library, obj.library_objects, obj.object_id = \
        "library", str(library), "one", object_id
    return cfg


def common_objects(libraries: list[str], split: str | None) -> list[str]:
    """The ids of `split` the first library lists; InputError naming a library that lacks one
    (the comparison needs the same objects in each)."""
    from corn_drake.assets.library import list_objects

    ids = list_objects(libraries[0], split)
    if not ids:
        raise InputError(f"--objects {libraries[0]}: no {split + ' ' if split else ''}objects")
    for library in libraries[1:]:
        missing = sorted(set(ids) - set(list_objects(library, split)))
        if missing:
            raise InputError(f"--objects {library} lacks {len(missing)} of {libraries[0]}'s "
                             f"objects ({', '.join(missing[:3])}...): build it with the same "
                             "--num-objects, --seed and --split")
    return ids


def hull_counts(library: str) -> dict[str, int | None]:
    """Object id -> its number of hulls (the manifest's count, else its hull files)."""
    from corn_drake.assets.manifest import read_manifest

    return {o.id: o.num_hulls if o.num_hulls is not None else (len(o.hulls) if o.hulls else None)
            for o in read_manifest(Path(library)).objects}


def measure_libraries(base_cfg, libraries: list[str], split: str | None, steps: int,
                      seed: int, repeats: int) -> dict:
    """Per object and library: hull count and bare-physics policy steps/s (the best of
    `repeats` replays, libraries alternating); means and ratios against the first library."""
    from corn_drake.bench.episode_plans import random_action_plans
    from corn_drake.bench.bare_physics import check_replayable, record_torques, replay_bare
    from corn_drake.rl.envs.teacher_env import TeacherEnv

    ids = common_objects(libraries, split)
    hulls = [hull_counts(library) for library in libraries]
    per_object = {}
    for object_id in ids:
        recorded = []
        for library in libraries:
            cfg = object_config(base_cfg, library, object_id)
            check_replayable(cfg)
            env = TeacherEnv(cfg)
            recorded.append((env, record_torques(env, random_action_plans(env, steps, seed))))
        rates = [0.0] * len(libraries)
        for _ in range(repeats):
            for i, (env, rec) in enumerate(recorded):
                rates[i] = max(rates[i], steps / replay_bare(env, rec)[0])
        per_object[object_id] = {
            "hulls": [counts[object_id] for counts in hulls],
            "bare_physics_policy_steps_per_s": rates,
            "ratio": [r / rates[0] for r in rates]}
        print(f"  {object_id}: hulls {per_object[object_id]['hulls']}, "
              f"{', '.join(f'{r:.0f}' for r in rates)} steps/s", flush=True)
    n = len(ids)
    return {
        "libraries": [str(lib) for lib in libraries],
        "split": split,
        "objects": per_object,
        "steps_per_object": steps,
        "mean_bare_physics_policy_steps_per_s": [
            sum(o["bare_physics_policy_steps_per_s"][i] for o in per_object.values()) / n
            for i in range(len(libraries))],
        "mean_hulls": [sum(o["hulls"][i] or 0 for o in per_object.values()) / n
                       for i in range(len(libraries))],
        "geometric_mean_ratio": [
            math.exp(sum(math.log(o["ratio"][i]) for o in per_object.values()) / n)
            for i in range(len(libraries))],
    }
