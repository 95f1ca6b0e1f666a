"""Lookahead data: at every state of an episode, each candidate primitive simulated from that
state, with what it did to the object. `corn-drake collect-outcomes` writes these; `corn-drake
fit-outcome` fits an outcome model (outcome/model.py) to them.

Why: a one-step lookahead over the agent's own candidate primitives (outcome/lookahead.py)
reaches push_turn's goals, the object at rest, in ~0.9 of unseen episodes where the TD3 policy
reaches ~0.13 (the primitive results, item 33): the primitives can do the task, and every
lookahead state gives the outcome of ~50 primitives from one state where a TD3 transition gives
one. A model of those outcomes is what the shipped full6d_outcome policy chooses by.

Data (collect_episode): at every state, the agent's features of the observation (the frozen
encoder's, agent.features) and every candidate's (location, motion, reward, the object's pose
after). The episode goes on with the lookahead's best primitive, or with probability
`follow_policy` with the agent's own greedy one, so the states are both the lookahead's and the
policy's (DAgger's mixture).

collect_chunks: episode k runs on the library's k-th training object (round-robin) with seed
COLLECT_SEED + k (not an evaluation seed); episodes are written `chunk` to a file
(episodes_KKKKK.npz, named by its first episode), each file atomically, and a file already
there is skipped, so a stopped collection resumes and parallel ones with other `start`s share
one folder.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from corn_drake.errors import InputError
from corn_drake.rl.primitive.outcome.lookahead import candidate_primitives, lookahead_step
from corn_drake.systems.control.low_push import push_contact

FEATURE_KEYS = ("tokens", "local", "global", "mask")
COLLECT_SEED = 5000  # episode k's seed is COLLECT_SEED + k: apart from evaluate's (1000...)
CHUNK_PATTERN = "episodes_*.npz"


def collect_episode(env, agent, seed: int, random_motions: int, follow_policy: float,
                    rng: np.random.Generator) -> tuple[list[dict], dict]:
    """(states, outcome) of one episode of `env` (a PrimitiveEnv, no policy inside) from
    reset(seed): each state {"features": {key: (L, ...) float32}, "outcome": {"pose" (7: the
    object's [p, q_wxyz]), "goal" (7), "corners" (8, 3: its box keypoints, body frame), "aims"
    (L, 3: where the executor aims at each location), "physics" (5)}, and per candidate
    "location" (K,), "motion" (K, 3), "reward" (K,), "pose_after" (K, 7), "still_after" (K,),
    "success_after" (K,)}; outcome {"success", "primitives"}. The pose, goal, corners and
    poses after recompute the rewards (tests/test_outcome_collect.py), so a model of the
    primitives' outcomes can be fitted to the same data."""
    if not 0.0 <= follow_policy <= 1.0:
        raise InputError(f"follow_policy must be in [0, 1], got {follow_policy}")
    obs, info = env.reset(seed=seed)
    states, status, primitives = [], info["status"], 0
    while True:
        features, _ = agent.features(obs)
        choice = agent.choose(obs)
        # What a model of the primitives' outcomes needs: where the object is, its goal and
        # its box keypoints (the reward's), besides every candidate's pose after.
        pose, goal = env.object_pose(), np.asarray(env.episode.goal_pose, float)
        corners = env.body_points("object_keypoints").astype(np.float64)
        # Where the executor aims for each location (a side push is lowered, low_push.py) and
        # the episode's physics (mass, frictions, restitution).
        aims = np.stack([push_contact(obs["cloud"], obs["normals"], int(i), env.primitive_cfg)[0]
                         for i in choice["candidates"]])
        candidates = candidate_primitives(choice, random_motions, rng)
        result = lookahead_step(env, candidates)
        states.append({"features": {k: features[k][0].numpy().astype(np.float32)
                                    for k in FEATURE_KEYS},
                       "outcome": {"pose": pose, "goal": goal, "corners": corners,
                                   "aims": aims, "physics": np.asarray(obs["physics"], float)},
                       "location": np.array([c[0] for c in candidates], np.int64),
                       "motion": np.array([c[2] for c in candidates], np.float32),
                       "reward": result.rewards.astype(np.float32),
                       "pose_after": result.poses.astype(np.float64),
                       "still_after": result.still.astype(bool),
                       "success_after": result.successes.astype(bool)})
        step = result.step
        if result.chosen != 0 and rng.random() < follow_policy:
            env.restore(result.start)  # the policy's own primitive instead (candidate 0)
            step = env.step({"point": candidates[0][1], "motion": candidates[0][2]})
        obs, _, terminated, truncated, info = step
        primitives += 1
        status = info.get("status", status)
        if terminated or truncated:
            return states, {"success": bool(status.get("success", 0) > 0),
                            "primitives": primitives}


def stack_states(states: list[dict]) -> dict[str, np.ndarray]:
    """The states as flat arrays: features per state (S, L, ...) and, when every state has
    them, its outcome parts (outcome_pose, outcome_goal, ...); candidates per row (state index,
    location, motion, reward, and pose_after, still_after, success_after with the outcomes)."""
    if not states:
        raise InputError("no lookahead states to stack")
    out = {f"features_{k}": np.stack([s["features"][k] for s in states]) for k in FEATURE_KEYS}
    out["state"] = np.concatenate([np.full(len(s["reward"]), i, np.int64)
                                   for i, s in enumerate(states)])
    for key in ("location", "motion", "reward"):
        out[key] = np.concatenate([s[key] for s in states])
    if all("outcome" in s for s in states):  # states collected with their outcomes
        for key in ("pose", "goal", "corners", "aims", "physics"):
            out[f"outcome_{key}"] = np.stack([s["outcome"][key] for s in states])
        for key in ("pose_after", "still_after", "success_after"):
            out[key] = np.concatenate([s[key] for s in states])
    return out


def chunk_path(out: Path, first: int) -> Path:
    """The file of the chunk whose first episode is `first` (name order is episode order)."""
    return Path(out) / f"episodes_{first:05d}.npz"


@dataclasses.dataclass
class Collection:
    """What every chunk of one collection is made with, checked and recorded once
    (prepare_collection): the proposing run's agent, the collecting env's settings, the
    library's training objects, and the chunks [first, last) still to write into `out`."""
    agent: object
    env: object  # the run's env config (its seed is COLLECT_SEED's for every object's env)
    primitive: object  # PrimitiveConfig with at_rest / settle_steps applied
    objects: Path
    ids: list[str]
    out: Path
    chunks: list[tuple[int, int]]
    random_motions: int
    follow_policy: float


def prepare_collection(run, objects, episodes: int, out, start: int = 0, chunk: int = 10,
                       random_motions: int = 2, follow_policy: float = 0.5,
                       at_rest: bool = False, settle_steps: int = 0, sets=()) -> Collection:
    """The Collection of episodes start .. start + episodes - 1 of primitive run `run`'s
    lookahead on library `objects`' training objects, `chunk` episodes to a file under `out`
    (module docstring), the chunks already there left out. `at_rest`: the env's success needs
    the object still at the end of a primitive (PrimitiveConfig.success_at_rest);
    `settle_steps`: periods the executor waits for the object to settle after each primitive;
    `sets`: env.* / primitive.* overrides as `evaluate --set` takes them. Bad inputs:
    InputError, nothing written."""
    from corn_drake.assets.content_hash import library_content_hash
    from corn_drake.assets.library import list_objects
    from corn_drake.config.plumbing.diagram_files import primitive_run_on
    from corn_drake.rl.checkpoints import agent_weights_folder, weights_hash
    from corn_drake.rl.primitive.agent import load_primitive_run
    from corn_drake.run_folders.inputs_record import check_inputs

    if episodes < 1 or chunk < 1 or start < 0 or random_motions < 0:
        raise InputError(f"episodes {episodes} and chunk {chunk} must be >= 1, start {start} "
                         f"and random_motions {random_motions} >= 0")
    if not 0.0 <= follow_policy <= 1.0:
        raise InputError(f"follow_policy must be in [0, 1], got {follow_policy}")
    ids = list_objects(objects, "train")
    if not ids:
        raise InputError(f"{objects}: no training objects to collect on")
    base, agent, _ = load_primitive_run(run)
    cfg = primitive_run_on(base, None, list(sets))
    primitive = dataclasses.replace(cfg.primitive, success_at_rest=at_rest,
                                    settle_steps=settle_steps)
    out = Path(out)
    # What the folder's files are made of: another run, library or setting added to it later
    # would mix data (processes with other --start values, or workers, share these).
    checkpoint = agent_weights_folder(Path(run), base.agent_weights) / "checkpoints" / \
        agent.checkpoint_file
    check_inputs(out, {"run_weights": weights_hash(Path(run), checkpoint),
                       "library": library_content_hash(objects, ids), "chunk": chunk,
                       "random_motions": random_motions, "follow_policy": follow_policy,
                       "at_rest": at_rest, "settle_steps": settle_steps, "sets": list(sets)},
                 "outcome data")
    end = start + episodes
    # A chunk already there is an earlier run's, whole (written atomically): kept.
    chunks = [(first, min(first + chunk, end)) for first in range(start, end, chunk)
              if not chunk_path(out, first).exists()]
    return Collection(agent, dataclasses.replace(cfg.env, seed=COLLECT_SEED), primitive,
                      Path(objects), ids, out, chunks, random_motions, follow_policy)


def collect_chunk(collection: Collection, first: int, last: int, envs: dict,
                  objects=None) -> tuple[dict[str, np.ndarray], list[dict]]:
    """(the arrays of chunk file `first`, one outcome row per episode) for episodes first ..
    last - 1. `envs` keeps one env per object across calls (each reset with its episode's
    seed); `objects`: the library's folder as this process reads it (a Ray worker's node copy;
    default the collection's). Episode k's data depends on k only, whichever process plays it."""
    from corn_drake.assets.library import load_object_spec
    from corn_drake.rl.envs.primitive_env import PrimitiveEnv

    objects = Path(objects) if objects is not None else collection.objects
    states, episode_of, object_of, rows = [], [], [], []
    for k in range(first, last):
        object_id = collection.ids[k % len(collection.ids)]
        if object_id not in envs:  # one env per object, reset with each episode's seed
            envs[object_id] = PrimitiveEnv(collection.env, collection.primitive,
                                           load_object_spec(objects, object_id))
        rng = np.random.default_rng(COLLECT_SEED + k)
        found, outcome = collect_episode(envs[object_id], collection.agent, COLLECT_SEED + k,
                                         collection.random_motions, collection.follow_policy,
                                         rng)
        states += found
        episode_of += [k] * len(found)
        object_of += [object_id] * len(found)
        rows.append({"episode": k, "object": object_id, **outcome})
    arrays = {**stack_states(states), "episode": np.array(episode_of, np.int64),
              "object": np.array(object_of)}
    return arrays, rows


def write_chunk(out, first: int, arrays: dict[str, np.ndarray]) -> Path:
    """Chunk file `first` under `out`, atomically (a stopped write leaves no part file)."""
    from corn_drake.storage.atomic_files import atomic_path

    path = chunk_path(out, first)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(f, **arrays)
    return path


def collect_chunks(run, objects, episodes: int, out, start: int = 0, chunk: int = 10,
                   random_motions: int = 2, follow_policy: float = 0.5, at_rest: bool = False,
                   settle_steps: int = 0, sets=(), log=print) -> list[Path]:
    """prepare_collection's chunks collected in this process and written (module docstring);
    returns the files written (those already there are skipped). `log` gets one JSON line per
    episode. (`collect-outcomes --workers N` plays the same chunks on Ray workers instead:
    rl/workers/outcome_workers.py.)"""
    import json

    collection = prepare_collection(run, objects, episodes, out, start, chunk, random_motions,
                                    follow_policy, at_rest, settle_steps, sets)
    envs, written = {}, []
    for first, last in collection.chunks:
        arrays, rows = collect_chunk(collection, first, last, envs)
        for row in rows:
            log(json.dumps(row))
        written.append(write_chunk(collection.out, first, arrays))
    return written
