"""How predictable is a primitive's outcome at all? README.md's item 36.

    .venv/bin/python docs/results/primitive/outcome_noise.py models/weights/full6d_outcome \
        --task push_turn --episodes 20 --out docs/results/primitive/outcome_noise.json

From states of episodes on the library's training objects (episode k: the k-th training
object, seed 7000 + k, not an evaluation seed), every candidate the run's chooser would weigh
at each usable location (its best motion there) is simulated from the same state twice more:
once exactly (the simulator is deterministic: the same outcome), once with the motion moved by
N(0, --perturb) per axis ([-1, 1] units: 0.02 is 3 mm of the 15 cm push, within what the
controller tracks). The distance between the two outcomes of such twins, in the reward's terms
(the mean distance between the object's box keypoints after them, the origin's height dropped),
is the part of the outcome no model of the primitive can predict; it is set against the
spread between different locations' outcomes and against how far the primitives move the
object. The episode then goes on with the best of the candidates (as the lookahead does). The
report is rewritten atomically after every episode.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from corn_drake.assets.library import list_objects, load_object_spec
from corn_drake.config.diagram_files import with_primitive_task
from corn_drake.rl.primitive.outcome.lookahead import lookahead_step
from corn_drake.rl.primitive.agent import load_primitive_run
from corn_drake.rl.envs.primitive_env import PrimitiveEnv
from corn_drake.storage.atomic_files import write_json
from corn_drake.systems.reward import keypoints_at
from corn_drake.transforms import quat_wxyz_to_matrix

SEED = 7000


def keypoint_distance(corners: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Mean distance (m) between the box keypoints at poses a and b ([p, q_wxyz])."""
    return float(np.linalg.norm(
        keypoints_at(corners, a[:3], quat_wxyz_to_matrix(a[3:])) -
        keypoints_at(corners, b[:3], quat_wxyz_to_matrix(b[3:])), axis=1).mean())


def state_figures(env, agent, obs, perturb: float, rng) -> tuple[dict, object]:
    """One state's figures, and its lookahead step (the env left after its best candidate)."""
    choice = agent.choose(obs)
    usable = np.flatnonzero(choice["usable"])
    base = [(int(loc), int(choice["candidates"][loc]), np.asarray(choice["motions"][loc], float))
            for loc in usable]
    twins = [(loc, point, np.clip(m + rng.normal(0.0, perturb, 3), -1.0, 1.0))
             for loc, point, m in base]
    repeat = [base[0]]
    start_pose = env.object_pose()
    corners = env.body_points("object_keypoints")
    step = lookahead_step(env, base + twins + repeat)
    n = len(base)
    poses, rewards = step.poses, step.rewards
    twin = [keypoint_distance(corners, poses[i], poses[n + i]) for i in range(n)]
    moved = [keypoint_distance(corners, start_pose, poses[i]) for i in range(n)]
    spread = [keypoint_distance(corners, poses[i], poses[j])
              for i in range(n) for j in range(i + 1, n)]
    best = int(np.argmax(rewards[:n]))
    return {"candidates": n,
            "twin_distance": float(np.mean(twin)),
            "spread_distance": float(np.mean(spread)) if spread else None,
            "moved_distance": float(np.mean(moved)),
            "repeat_distance": keypoint_distance(corners, poses[0], poses[-1]),
            "twin_reward_difference": float(np.mean(np.abs(rewards[:n] - rewards[n:2 * n]))),
            "reward_spread": float(np.std(rewards[:n])),
            "best_reward": float(rewards[best]),
            "best_twin_reward": float(rewards[n + best]),
            "chosen_reward": float(rewards[int(np.flatnonzero(usable == choice["location"])[0])])
            if choice["location"] in usable else None}, step


def summary(states: list[dict]) -> dict:
    def mean(key):
        values = [s[key] for s in states if s[key] is not None]
        return float(np.mean(values)) if values else None
    return {"states": len(states),
            **{key: mean(key) for key in ("twin_distance", "spread_distance", "moved_distance",
                                          "repeat_distance", "twin_reward_difference",
                                          "reward_spread", "best_reward", "best_twin_reward",
                                          "chosen_reward")},
            "repeat_distance_max": float(max(s["repeat_distance"] for s in states))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run")
    parser.add_argument("--task", default=None)
    parser.add_argument("--objects", default="data/library")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--perturb", type=float, default=0.02)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    base, agent, _ = load_primitive_run(args.run)
    if args.task is not None:
        base = with_primitive_task(base, args.task)
    agent.task = base.env.task
    ids = list_objects(args.objects, "train")
    states, episodes = [], []
    for k in range(args.episodes):
        object_id = ids[k % len(ids)]
        env = PrimitiveEnv(dataclasses.replace(base.env, seed=SEED), base.primitive,
                           load_object_spec(args.objects, object_id))
        rng = np.random.default_rng(SEED + k)
        obs, _ = env.reset(seed=SEED + k)
        while True:
            figures, step = state_figures(env, agent, obs, args.perturb, rng)
            states.append({"episode": k, "object": object_id, **figures})
            obs, _, terminated, truncated, _ = step.step
            if terminated or truncated:
                break
        episodes.append({"episode": k, "object": object_id,
                         "states": sum(s["episode"] == k for s in states)})
        write_json(args.out, {"run": args.run, "task": base.env.task.name,
                              "perturb": args.perturb, "episodes": episodes,
                              "summary": summary(states), "states": states})
        print(f"episode {k} ({object_id}): {episodes[-1]['states']} states; so far "
              f"{summary(states)}", flush=True)


if __name__ == "__main__":
    main()
