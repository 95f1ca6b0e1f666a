"""`corn-drake evaluate --run planner`: the 6D expert (rl/planner/) on evaluate's fixed
episodes, resumable and splittable by episode range; its labels kept beside the rows.

Episode k is evaluate's episode k (its object ids[k % len(ids)], seeded episode_seed(seed,
object, k // len(ids)), the env's seed the base seed as policy_env sets it), so a planner report
compares row by row with any policy's. Each finished episode is appended at once as one JSON
line to REPORT.rows.jsonl (its first line: the settings); a rerun with the same settings skips
the episodes already there, and `--episodes-from A --episodes N` plays only k in [A, N), so the
200 episodes can be spread over processes writing different reports (merge-reports joins
them), or over Ray workers (planner_workers.py). The report is rewritten after every episode.

Each row is planner_play.play's. What every decision's search found of each root candidate
(its reward and, in the beam, its value: search.label_of) goes to REPORT.labels.jsonl.gz, one
line per episode (its first line: the settings and the columns), written before the episode's
row: the labels a learned chooser is fitted to, kept out of the report. They are gzipped a line
per member (storage/gz_lines.py: a fifth of the size, still appended a line at a time).
"""

from __future__ import annotations

import dataclasses
import json
from collections import Counter
from pathlib import Path

import numpy as np

from corn_drake.errors import InputError
from corn_drake.evaluation.episode_rows import (append_row, claim_range, read_rows,
                                                 rows_path_of)
from corn_drake.evaluation.episodes import episode_seed
from corn_drake.evaluation.planner_play import Labeller, play
from corn_drake.evaluation.report_core import episode_report
from corn_drake.storage.atomic_files import write_json


def read_labels_by_episode(path: Path, settings: dict) -> dict[int, dict]:
    """The episode labels of `path` (REPORT.labels.jsonl.gz, or the plain REPORT.labels.jsonl
    an older run wrote; rl/planner/labels.read_labels) by episode; {} for neither. A file of
    another evaluation's labels is refused, as its rows file would be."""
    from corn_drake.rl.planner.labels import plain_path_of, read_labels

    if not path.exists():
        path = plain_path_of(path)
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
    """REPORT.labels.jsonl.gz beside REPORT.rows.jsonl."""
    from corn_drake.rl.planner.labels import LABELS_SUFFIX

    return rows_path.with_name(rows_path.name.replace(".rows.jsonl", LABELS_SUFFIX))


def report_of(rows: list[dict], task, requested, facts: dict) -> dict:
    """The report of `rows` (episodes of `requested`, a range or sorted list of k): the keys
    every report shares (report_core.episode_report) and the expert's decisions and costs."""
    decisions = [d for r in rows for d in r["decisions"]]
    cpu = float(sum(r["cpu_seconds"] for r in rows))
    shared = episode_report(rows, requested)
    episodes = {k: shared.pop(k) for k in ("episodes_from", "episodes_requested", "complete",
                                           "episodes")}
    return {"task": task.name, **facts, **shared,
            "hacman_success_rate": shared.get("hacman_success_rate"),
            "decisions": len(decisions),
            "simulated_per_decision": float(np.mean([d["simulated"] for d in decisions]))
            if decisions else None,
            "cpu_seconds_per_decision": float(np.mean([d["cpu_seconds"] for d in decisions]))
            if decisions else None,
            "cpu_seconds": cpu,
            "decisions_per_core_hour": 3600.0 * len(decisions) / cpu if decisions else None,
            "kinds_chosen": dict(sum((Counter(r["kinds_chosen"]) for r in rows), Counter())),
            **episodes}


def evaluate_planner(policy, cfg, objects, episodes: range, seed: int, report_path: Path,
                     progress: bool = False, labeller: Labeller | None = None,
                     facts: dict | None = None, workers: int = 0, ray_address: str = "",
                     library: Path | None = None) -> dict:
    """Plays evaluate's episodes `episodes` (a range of k) of `policy` (search.PlannerPolicy)
    round-robin over `objects` [(id, ObjectSpec)] in `cfg`'s env, resuming REPORT.rows.jsonl.
    With a `labeller` the states are labelled along its mixture of expert and learner
    (`corn-drake label`); `facts` are more settings the rows and labels files keep (the
    library's content hash). With `workers` the episodes run on that many Ray workers (a
    cluster's at `ray_address`; the objects of `library`, when they come from one, sent
    through the object store): planner_workers.py."""
    from tqdm import tqdm

    from corn_drake.rl.envs.primitive_env import PrimitiveEnv
    from corn_drake.rl.planner.labels import gzip_plain_labels
    from corn_drake.rl.planner.search import LABEL_COLUMNS
    from corn_drake.storage.gz_lines import append_line, cut_after, read_lines

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
    rows_path = rows_path_of(report_path)
    labels_path = labels_path_of(rows_path)
    rows = read_rows(rows_path, settings)
    # Another evaluation's labels: refused before any episode (and before any file changes).
    read_labels_by_episode(labels_path, settings)
    gzip_plain_labels(labels_path)
    claim_range(rows_path, settings, episodes, rows)
    _, whole = read_lines(labels_path) if labels_path.exists() else ([], None)
    if whole is not None:  # a member a kill cut short: its episode is played again
        cut_after(labels_path, whole)
    if not labels_path.exists():
        append_line(labels_path, {"settings": settings, "columns": LABEL_COLUMNS})
    done = {r["episode"] for r in rows}
    bar = tqdm(total=len(episodes), initial=len(done), desc="episodes", unit="episode",
               disable=not progress)
    jobs = []
    for k in episodes:
        if k not in done:
            object_id, spec = objects[k % len(objects)]
            jobs.append((k, object_id, spec, episode_seed(seed, object_id, k // len(objects))))

    def finished(row: dict) -> None:
        # The labels first: a kill between the two lines replays the episode, and a reader
        # keeps an episode's last labels line.
        append_line(labels_path, {"episode": row["episode"], "object": row["object"],
                                  "seed": row["seed"], "decisions": row.pop("labels")})
        append_row(rows_path, row)
        rows.append(row)
        write_json(report_path, report_of(sorted(rows, key=lambda r: r["episode"]), cfg.task,
                                          episodes, facts))
        bar.set_postfix(successes=sum(r["success"] for r in rows), refresh=False)
        bar.update()

    if workers:
        from corn_drake.evaluation.planner_workers import play_on_workers
        from corn_drake.rl.workers.cluster import pack_objects
        from corn_drake.rl.workers.ray_workers import init_ray

        init_ray(ray_address or None)
        packed = pack_objects(library, [o for o, _ in objects]) if library else None
        if packed is not None:  # the workers read the objects from their node's copy
            jobs = [(k, object_id, None, seed_k) for k, object_id, _, seed_k in jobs]
        play_on_workers(jobs, policy, cfg, labeller.facts if labeller else None, packed,
                        workers, finished)
    else:
        env, env_object, planner = None, None, policy.planner(cfg.task)
        for k, object_id, spec, seed_k in jobs:
            if object_id != env_object:  # one env alive
                env, env_object = PrimitiveEnv(cfg, policy.primitive, spec), object_id
            finished({"episode": k, "object": object_id, "seed": seed_k,
                      **play(env, planner, seed_k, labeller)})
    bar.close()
    return report_of(sorted(rows, key=lambda r: r["episode"]), cfg.task, episodes, facts)
