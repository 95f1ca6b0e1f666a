"""Can the primitives do the task at all? A one-step lookahead with the simulator as its model
(corn_drake/rl/primitive/outcome/lookahead.py) against the learned policy's greedy choices, on the first
episodes of `evaluate`'s unseen-object episodes: experiments/primitive_policy/LOG.md's items 33, 40.

    .venv/bin/python -m experiments.primitive_outcomes.lookahead_oracle \
        models/weights/push_turn_primitive \
        --task push_turn --episodes 23 --random-motions 2 \
        --out docs/results/primitive/lookahead_push_turn.json
    (the same with --at-rest --out docs/results/primitive/lookahead_push_turn_at_rest.json)

Episode k is `evaluate --split unseen --seed 1000`'s episode k (the same object, seed and env
settings as the run's eval reports). Each episode is played twice from its start:
- `policy`: the run's policy choosing greedily from outside the diagram (PrimitiveEnv.step);
- `lookahead`: at every primitive, each candidate (the policy's choice, its actor's motion at
  every other usable location, and `--random-motions` uniform motions per usable location) is
  simulated from the same state, and the one with the most reward is kept.
With --at-rest a success counts only when a primitive has ended with the object at the goal and
still (PrimitiveConfig.success_at_rest; the task's own rule counts a pose the object passes
through mid-push), in both arms. Each finished episode is written to --out at once (atomically), and a rerun with the same
arguments carries on after the episodes already there. Prints the summary at the end.
`--set primitive.FIELD=VALUE` changes the executor in both arms (e.g. fewer primitives).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections import Counter
from pathlib import Path

import numpy as np

from corn_drake.assets.library import list_objects, load_object_spec
from corn_drake.config.diagram_files import load_primitive_env_config
from corn_drake.config.overrides import apply_sets
from corn_drake.errors import InputError
from corn_drake.evaluation.episodes import episode_seed
from corn_drake.evaluation.failures import (failure_category, motion_summary,
                                            successes_ending_still)
from corn_drake.rl.primitive.outcome.lookahead import candidate_primitives, lookahead_step
from corn_drake.rl.primitive.agent import load_primitive_run
from corn_drake.rl.envs.primitive_env import PrimitiveEnv
from corn_drake.storage.atomic_files import write_json

EVAL_SEED = 1000  # evaluate's default --seed


def play(env, agent, seed: int, random_motions: int | None) -> dict:
    """One episode from its start; `random_motions` None: the policy's greedy choices."""
    obs, info = env.reset(seed=seed)
    start = env.object_pose()
    rng = np.random.default_rng(seed)
    status, sim_error, steps, chosen_kinds, gains = info["status"], None, 0, Counter(), []
    greedy_count = None
    while True:
        choice = agent.choose(obs)
        if random_motions is None:
            obs, _, terminated, truncated, info = env.step({"point": choice["point"],
                                                            "motion": choice["motion"]})
        else:
            candidates = candidate_primitives(choice, random_motions, rng)
            greedy_count = len(candidates) - random_motions * int(choice["usable"].sum())
            result = lookahead_step(env, candidates)
            obs, _, terminated, truncated, info = result.step
            chosen_kinds["greedy" if result.chosen == 0 else
                         "actor" if result.chosen < greedy_count else "random"] += 1
            gains.append(float(result.rewards[result.chosen] - result.greedy_reward))
        steps += 1
        status, sim_error = info.get("status", status), info.get("sim_error")
        if terminated or truncated:
            break
    row = {"success": bool(status.get("success", 0) > 0), "primitives": steps,
           "position_error": status.get("position_error"),
           "orientation_error": status.get("orientation_error"), "sim_error": sim_error,
           "out_of_workspace": bool(status.get("out_of_workspace", 0) > 0),
           "motion": motion_summary(start, env.object_pose(), np.asarray(env.episode.goal_pose)),
           "end_speed": env.object_speed()}
    row["failure"] = failure_category(row, env.teacher_cfg.task)
    if random_motions is not None:
        row["chosen"] = dict(chosen_kinds)
        row["mean_reward_gain_over_greedy"] = float(np.mean(gains))
    return row


def summary(rows: list[dict], arm: str) -> dict:
    played = [r[arm] for r in rows]
    return {"episodes": len(played),
            "success_rate": float(np.mean([r["success"] for r in played])) if played else None,
            "failure_counts": dict(Counter(r["failure"] for r in played).most_common()),
            # The task's rule has no stillness check: a success can be a pose passed through.
            "successes_ending_still": successes_ending_still(played)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", help="a primitive run or shipped folder")
    parser.add_argument("--objects", default="data/library")
    parser.add_argument("--task", default=None, help="the run's own task unless given")
    parser.add_argument("--episodes", type=int, default=23)
    parser.add_argument("--random-motions", type=int, default=2)
    parser.add_argument("--at-rest", action="store_true",
                        help="success only at the end of a primitive with the object still "
                             "(PrimitiveConfig.success_at_rest), in both arms")
    parser.add_argument("--set", action="append", default=[], dest="set", metavar="KEY=VALUE",
                        help="primitive.* settings of the executor, in both arms")
    parser.add_argument("--out", required=True, type=Path)
    args = parser.parse_args()
    if args.episodes < 1:
        raise SystemExit(f"--episodes must be >= 1, got {args.episodes}")
    base, agent, trained = load_primitive_run(args.run)
    cfg = base.env
    if args.task is not None:  # as evaluate --task does for a primitive run
        cfg = load_primitive_env_config(args.task)
        cfg.scene.object = base.env.scene.object
    cfg = dataclasses.replace(cfg, seed=EVAL_SEED)
    ids = list_objects(args.objects, "unseen")
    if not ids:
        raise InputError(f"no unseen objects in library {args.objects}")
    primitive = dataclasses.replace(agent.primitive_config, success_at_rest=args.at_rest)
    if args.set:
        primitive = apply_sets(dataclasses.replace(base, primitive=primitive), args.set,
                               only="primitive").primitive
    settings = {"run": args.run, "task": cfg.task.name, "objects": args.objects,
                "random_motions": args.random_motions, "primitives_trained": trained,
                "success_at_rest": args.at_rest}
    if args.set:  # only then, so that the reports written before --set still resume
        settings["set"] = args.set
    rows = []
    if args.out.exists():
        done = json.loads(args.out.read_text())
        if done["settings"] != settings:
            raise SystemExit(f"{args.out} holds another study ({done['settings']}); "
                             "choose another --out")
        rows = done["episodes"]
    envs = {}
    for k in range(len(rows), args.episodes):
        object_id = ids[k % len(ids)]
        if object_id not in envs:
            envs[object_id] = PrimitiveEnv(cfg, primitive,
                                           load_object_spec(args.objects, object_id))
        seed = episode_seed(EVAL_SEED, object_id, k // len(ids))
        env = envs[object_id]
        rows.append({"episode": k, "object": object_id, "seed": seed,
                     "policy": play(env, agent, seed, None),
                     "lookahead": play(env, agent, seed, args.random_motions)})
        write_json(args.out, report_of(settings, rows))
        print(f"episode {k} {object_id}: policy {rows[-1]['policy']['failure']}, "
              f"lookahead {rows[-1]['lookahead']['failure']}", flush=True)
    report = report_of(settings, rows)
    print(json.dumps({k: v for k, v in report.items() if k != "episodes"}, indent=1))


def report_of(settings: dict, rows: list[dict]) -> dict:
    return {"settings": settings, "policy": summary(rows, "policy"),
            "lookahead": summary(rows, "lookahead"), "episodes": rows}


if __name__ == "__main__":
    main()
