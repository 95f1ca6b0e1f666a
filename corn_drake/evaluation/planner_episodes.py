"""`corn-drake evaluate --run planner`: the 6D expert (rl/planner/) on evaluate's fixed
episodes, resumable and splittable by episode range; its labels kept beside the rows.

Episode k is evaluate's episode k (its object ids[k % len(ids)], seeded episode_seed(seed,
object, k // len(ids)), the env's seed the base seed as policy_env sets it), so a planner report
compares row by row with any policy's. Each finished episode is appended at once as one JSON
line to REPORT.rows.jsonl (its first line: the settings); a rerun with the same settings skips
the episodes already there, and `--episodes-from A --episodes N` plays only k in [A, N), so the
200 episodes can be spread over processes writing different reports (their rows files
concatenate). The report is rewritten after every episode.

Each row adds to evaluate's: the planner's decisions (simulated primitives and CPU seconds
each, the sources chosen) and HACMan's criterion beside the task's success (`hacman_success`:
the mean distance between the object's cloud points at the end and at the goal under 3 cm, the
object at rest). What every decision's search found of each root candidate (its reward and,
in the beam, its value: search.label_of) goes to REPORT.labels.jsonl, one line per episode
(its first line: the settings and the columns), written before the episode's row: the labels a
learned chooser is fitted to, kept out of the report.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

from corn_drake.config.primitive import at_rest
from corn_drake.errors import InputError
from corn_drake.evaluation.episodes import episode_seed
from corn_drake.evaluation.failures import (failure_category, failure_counts, motion_summary,
                                            successes_ending_still)
from corn_drake.storage.atomic_files import write_json, write_text
from corn_drake.transforms import quat_wxyz_to_matrix

HACMAN_DISTANCE_M = 0.03


def cloud_distance(cloud_world: np.ndarray, pose, goal) -> float:
    """Mean distance (m) between the object's points where they are (`cloud_world`, taken at
    `pose`) and where they would be at `goal` (HACMan's success measure)."""
    pose, goal = np.asarray(pose, float), np.asarray(goal, float)
    R, Rg = quat_wxyz_to_matrix(pose[3:]), quat_wxyz_to_matrix(goal[3:])
    body = (np.asarray(cloud_world, float) - pose[:3]) @ R
    return float(np.linalg.norm(body @ Rg.T + goal[:3] - cloud_world, axis=1).mean())


def play(env, planner, seed: int, labeller: "Labeller | None" = None) -> dict:
    """One episode of `planner` on `env` (a PrimitiveEnv with no policy inside) from its start
    (the search's draws seeded by the episode's seed); the report row, its decisions' labels
    under "labels". With a `labeller` every state is searched (labelled) as always, but the
    primitive executed is its learner's where its coin says so (DAgger)."""
    obs, info = env.reset(seed=seed)
    planner.reset(seed)
    coin = None if labeller is None else labeller.coin(seed)
    start = env.object_pose()
    status, sim_error, started = info["status"], None, time.process_time()
    while True:
        if labeller is None:
            obs, _, terminated, truncated, info = planner.act(env, obs)
        else:
            obs, _, terminated, truncated, info = labeller.step(planner, env, obs, coin)
        status, sim_error = info.get("status", status), info.get("sim_error")
        if terminated or truncated:
            break
    end, goal = env.object_pose(), np.asarray(env.episode.goal_pose, float)
    labels = [{"chosen": d["chosen"], "executed": d["executed"], "pose": d["pose"],
               "labels": d["labels"], "children": d["children"],
               **({"actor": d["actor"]} if "actor" in d else {})} for d in planner.decisions]
    decisions = [{k: v for k, v in d.items()
                  if k not in ("labels", "executed", "pose", "children")}
                 for d in planner.decisions]
    distance = None if sim_error else cloud_distance(obs["cloud"], end, goal)
    row = {"success": bool(status.get("success", 0) > 0), "steps": int(env.steps),
           "primitives": len(decisions),
           "position_error": status.get("position_error"),
           "orientation_error": status.get("orientation_error"), "sim_error": sim_error,
           "out_of_workspace": bool(status.get("out_of_workspace", 0) > 0),
           "motion": motion_summary(start, end, goal), "end_speed": env.object_speed(),
           "hacman_distance": distance,
           "hacman_success": bool(distance is not None and distance < HACMAN_DISTANCE_M
                                  and at_rest(env.object_speed())),
           "kinds_chosen": dict(Counter(d["source"] for d in decisions)),
           "simulated": int(sum(d["simulated"] for d in decisions)),
           "cpu_seconds": float(time.process_time() - started),
           "decisions": decisions, "labels": labels}
    row["failure"] = failure_category(row, env.teacher_cfg.task)
    return row


@dataclasses.dataclass
class Labeller:
    """DAgger's mixture for `corn-drake label`: at every state the expert searches (its labels
    are kept as always) and then the expert's choice is executed with probability `beta`, else
    the `learner`'s (a PrimitiveAgent aimed at the evaluation's executor and task), so the
    labels describe the states the learner visits. The coin is seeded per episode apart from the
    search's generator: the search's draws are those of an expert-only episode up to the first
    state the learner changes."""
    learner: object
    beta: float
    facts: dict  # what the labels' settings say of the mixture: learner, beta

    def coin(self, seed: int) -> np.random.Generator:
        return np.random.default_rng([seed, COIN_STREAM])

    def step(self, planner, env, obs, coin) -> tuple:
        start = env.snapshot()
        decision, branch = planner.search(env, obs)
        if coin.random() < self.beta:
            env.restore(branch.snapshot)
            step, decision["actor"] = branch.step, "expert"
        else:
            env.restore(start)
            choice = self.learner.choose(obs)
            action = {"point": int(choice["point"]),
                      "motion": np.asarray(choice["motion"], float)}
            step = env.step(action)
            decision.update(actor="learner", reward=float(step[1]),
                            executed={"point": action["point"],
                                      "motion": [float(m) for m in action["motion"]]})
        planner.decisions.append(decision)
        obs, reward, terminated, truncated, info = step
        return obs, reward, terminated, truncated, dict(info, planner=decision)


COIN_STREAM = 1  # the labeller's coin: a stream of the episode's seed the search never draws


def read_rows(path: Path, settings: dict | None, repair: bool = True,
              notes: list | None = None) -> list[dict]:
    """The episode rows of `path` written with `settings` (None: whichever it names; read
    `settings_of` for them). A last line that a kill cut short is dropped (its episode was not
    finished): from the file too with `repair` (a resume), else only said in `notes`."""
    if not path.exists():
        return []
    lines = path.read_text().splitlines()
    records = []
    for i, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            if i != len(lines) - 1:
                raise InputError(f"{path}: line {i + 1} is not a JSON row; the file is damaged"
                                 ) from None
            if repair:
                write_text(path, "".join(f"{json.dumps(r)}\n" for r in records))
            elif notes is not None:
                notes.append(f"{path}: its last line is cut short (a kill mid-write); that "
                             "episode is not counted")
    if not records or "settings" not in records[0]:
        raise InputError(f"{path}: not a planner rows file (its first line names no settings)")
    if settings is not None and records[0]["settings"] != settings:
        raise InputError(f"{path} holds another planner evaluation's rows (other settings); "
                         "choose another --report")
    return records[1:]


def claim_range(rows_path: Path, settings: dict, episodes: range, rows: list[dict]) -> None:
    """Writes the rows file's header, {"settings", "requested": [first, stop)}: the episodes
    this evaluation was asked for, which merge-reports checks a part against. A resume asks for
    the same range or one holding it (the header then says the larger); another range is
    refused, naming both. A file from before the header said its range gets one when all its
    rows lie in the range asked for."""
    header = {"settings": settings, "requested": [episodes.start, episodes.stop]}
    if not rows_path.exists():
        _append(rows_path, header)
        return
    lines = rows_path.read_text().splitlines()
    before = json.loads(lines[0]).get("requested")
    had = range(*before) if before else range(min((r["episode"] for r in rows), default=0),
                                              max((r["episode"] for r in rows), default=-1) + 1)
    if had.start < episodes.start or had.stop > episodes.stop:
        if before or rows:
            raise InputError(f"{rows_path} holds the evaluation of episodes {had.start}.."
                             f"{had.stop - 1}; ask for a range holding it (--episodes-from "
                             f"{had.start} --episodes {had.stop}) or give another --report")
    if before != header["requested"]:
        write_text(rows_path, "\n".join([json.dumps(header), *lines[1:]]) + "\n")


def read_labels_by_episode(path: Path, settings: dict) -> dict[int, dict]:
    """The episode labels of `path` (REPORT.labels.jsonl, rl/planner/labels.read_labels) by
    episode; {} for no file. A file of another evaluation's labels is refused, as its rows file
    would be."""
    from corn_drake.rl.planner.labels import read_labels

    if not path.exists():
        return {}
    try:
        found, _, records = read_labels(path)
    except InputError:
        found = None
    if found != settings:
        raise InputError(f"{path} holds another evaluation's labels (or none); choose another "
                         "--report")
    return {record["episode"]: record for record in records}


def labels_path_of(rows_path: Path) -> Path:
    """REPORT.labels.jsonl beside REPORT.rows.jsonl."""
    return rows_path.with_name(rows_path.name.replace(".rows.jsonl", ".labels.jsonl"))


def settings_of(path: Path) -> dict:
    lines = path.read_text().splitlines() if path.is_file() else []
    if not lines:
        raise InputError(f"{path}: no such planner rows file")
    try:
        return json.loads(lines[0])["settings"]
    except (json.JSONDecodeError, KeyError, TypeError):
        raise InputError(f"{path}: not a planner rows file (its first line names no settings)"
                         ) from None


def _append(path: Path, record: dict) -> None:
    with open(path, "a") as f:
        f.write(json.dumps(record) + "\n")
        f.flush()
        os.fsync(f.fileno())


def report_of(rows: list[dict], task, requested, facts: dict) -> dict:
    """The report of `rows` (episodes of `requested`, a range or sorted list of k)."""
    per_object = defaultdict(list)
    for r in rows:
        per_object[r["object"]].append(r["success"])
    rates = {o: float(np.mean(s)) for o, s in per_object.items()}
    decisions = [d for r in rows for d in r["decisions"]]
    n, k = len(rows), sum(r["success"] for r in rows)
    return {"task": task.name, **facts,
            "success_rate": float(k / n) if n else None,
            "success_wilson_95": wilson(k, n),
            "hacman_success_rate": float(np.mean([r["hacman_success"] for r in rows]))
            if n else None,
            "balanced_success_rate": float(np.mean(list(rates.values()))) if rates else None,
            "per_object": rates,
            "mean_episode_length": float(np.mean([r["steps"] for r in rows])) if n else None,
            "failure_counts": failure_counts(rows),
            "successes_ending_still": successes_ending_still(rows),
            "decisions": len(decisions),
            "simulated_per_decision": float(np.mean([d["simulated"] for d in decisions]))
            if decisions else None,
            "cpu_seconds_per_decision": float(np.mean([d["cpu_seconds"] for d in decisions]))
            if decisions else None,
            "cpu_seconds": float(sum(r["cpu_seconds"] for r in rows)),
            "decisions_per_core_hour": 3600.0 * len(decisions) / sum(
                r["cpu_seconds"] for r in rows) if decisions else None,
            "kinds_chosen": dict(sum((Counter(r["kinds_chosen"]) for r in rows), Counter())),
            "episodes_from": min(requested, default=0), "episodes_requested": len(requested),
            "complete": n == len(requested), "episodes": rows}


def wilson(k: int, n: int, z: float = 1.96) -> list[float] | None:
    """The 95 % Wilson score interval of k successes in n."""
    if n == 0:
        return None
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return [float(centre - half), float(centre + half)]


def evaluate_planner(policy, cfg, objects, episodes: range, seed: int, report_path: Path,
                     progress: bool = False, labeller: Labeller | None = None,
                     facts: dict | None = None) -> dict:
    """Plays evaluate's episodes `episodes` (a range of k) of `policy` (search.PlannerPolicy)
    round-robin over `objects` [(id, ObjectSpec)] in `cfg`'s env, resuming REPORT.rows.jsonl.
    With a `labeller` the states are labelled along its mixture of expert and learner
    (`corn-drake label`); `facts` are more settings the rows and labels files keep (the
    library's content hash)."""
    from tqdm import tqdm

    from corn_drake.rl.envs.primitive_env import PrimitiveEnv
    from corn_drake.rl.planner.search import LABEL_COLUMNS

    if not objects:
        raise InputError("evaluate: no objects to evaluate on")
    if len(episodes) < 1:
        raise InputError(f"evaluate: no episodes in [{episodes.start}, {episodes.stop})")
    cfg = dataclasses.replace(cfg, seed=seed)  # as policy_env: the env's seed is the base seed
    facts_more, facts = facts, policy.describe()
    settings = {"task": cfg.task.name, "seed": seed, **facts,
                "objects": [o for o, _ in objects],
                **(labeller.facts if labeller is not None else {}), **(facts_more or {})}
    settings = json.loads(json.dumps(settings))  # as it reads back
    rows_path = report_path.with_name(report_path.stem + ".rows.jsonl")
    labels_path = labels_path_of(rows_path)
    rows = read_rows(rows_path, settings)
    # Another evaluation's labels: refused before any episode.
    read_labels_by_episode(labels_path, settings)
    claim_range(rows_path, settings, episodes, rows)
    if not labels_path.exists():
        _append(labels_path, {"settings": settings, "columns": LABEL_COLUMNS})
    done = {r["episode"] for r in rows}
    envs, planner = {}, policy.planner(cfg.task)
    bar = tqdm(total=len(episodes), initial=len(done), desc="episodes", unit="episode",
               disable=not progress)
    for k in episodes:
        if k in done:
            continue
        object_id, spec = objects[k % len(objects)]
        if object_id not in envs:
            envs = {object_id: PrimitiveEnv(cfg, policy.primitive, spec)}  # one env alive
        seed_k = episode_seed(seed, object_id, k // len(objects))
        row = {"episode": k, "object": object_id, "seed": seed_k,
               **play(envs[object_id], planner, seed_k, labeller)}
        # The labels first: a kill between the two lines replays the episode, and a reader
        # keeps an episode's last labels line.
        _append(labels_path, {"episode": k, "object": object_id, "seed": seed_k,
                              "decisions": row.pop("labels")})
        _append(rows_path, row)
        rows.append(row)
        write_json(report_path, report_of(sorted(rows, key=lambda r: r["episode"]), cfg.task,
                                          episodes, facts))
        bar.set_postfix(successes=sum(r["success"] for r in rows), refresh=False)
        bar.update()
    bar.close()
    return report_of(sorted(rows, key=lambda r: r["episode"]), cfg.task, episodes, facts)
