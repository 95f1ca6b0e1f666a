"""One episode of the 6D expert (`play`): the search at every state, the primitive executed
(the expert's, or with a `Labeller` DAgger's mix of expert and learner), and the row a report
keeps of it, its labels under "labels". Played in this process by planner_episodes.py or in a
Ray worker by planner_workers.py.

Each row adds to evaluate's: the planner's decisions (simulated primitives and CPU seconds
each, the sources chosen) and HACMan's criterion beside the task's success (`hacman_success`:
the mean distance between the object's cloud points at the end and at the goal under 3 cm, the
object at rest).
"""

from __future__ import annotations

import dataclasses
import time
from collections import Counter

import numpy as np

from corn_drake.config.primitive import at_rest
from corn_drake.evaluation.failures import failure_category, motion_summary
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


def labeller_of(facts: dict, primitive, task) -> Labeller:
    """The Labeller `facts` ({"learner": run folder, "beta"}) describe, its learner loaded and
    aimed at the evaluation's executor settings and task."""
    from corn_drake.rl.planner.sources import load_policy

    return Labeller(load_policy(facts["learner"], primitive, task), float(facts["beta"]),
                    dict(facts))
