"""How often a primitive policy's single primitives tip or roll the object, and how far they turn
it against its goal, on push_turn's unseen episodes: the measurements behind README.md's item 9
("Why objects tip") and item 31 (how the pushes turn the objects).

    .venv/bin/python docs/results/primitive/tipping_per_primitive.py models/weights/push_primitive \
        --episodes 23
    .venv/bin/python docs/results/primitive/tipping_per_primitive.py models/weights/push_primitive \
        --episodes 46 --set push_height=0.02 --set finger_tilt_deg=30 --set approach_steps=30

Episode k runs on the library's k-th unseen object (round-robin) with seed 1000 + k, the policy
acting greedily from outside the diagram (PrimitiveEnv.step, one primitive per step). A primitive
"tips" when the object's up axis turns more than 0.5 rad during it (the failure table's rule,
evaluation/failures.py). Of the primitives that do not tip, it also records the object's
rotation during the primitive and the rotation error to the goal before and after it
(PrimitiveEnv.rotation_to_goal, the task's own error). Prints one JSON object: primitives,
tipping, their share, tipping primitives per object, and the turn figures (`turn`).
"""

from __future__ import annotations

import argparse
import collections
import json

import numpy as np

from corn_drake.assets.manifest import read_manifest
from corn_drake.config.diagram_files import load_primitive_env_config
from corn_drake.rl.primitive.agent import load_primitive_run
from corn_drake.rl.envs.primitive_env import PrimitiveEnv
from corn_drake.tasks.faces import TIPPED_ANGLE_RAD
from corn_drake.transforms import quat_wxyz_to_matrix, rotation_angle, up_angle


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", help="a primitive run or shipped folder")
    parser.add_argument("--objects", default="data/library")
    parser.add_argument("--task", default="push_turn")
    parser.add_argument("--episodes", type=int, default=23)
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="a PrimitiveConfig field for the executor (e.g. push_height=0.02)")
    args = parser.parse_args()
    _, agent, _ = load_primitive_run(args.run)
    primitive = agent.primitive_config
    for item in args.set:
        field, value = item.split("=", 1)
        setattr(primitive, field, type(getattr(primitive, field))(value))
    unseen = [o.id for o in read_manifest(args.objects).objects if o.split == "unseen"]
    tipping, total = collections.Counter(), 0
    turns, before_errors, after_errors = [], [], []  # the primitives that do not tip
    for k in range(args.episodes):
        cfg = load_primitive_env_config(args.task)
        o = cfg.scene.object
        o.kind, o.library, o.object_id = "library", args.objects, unseen[k % len(unseen)]
        env = PrimitiveEnv(cfg, primitive)
        obs, _ = env.reset(seed=1000 + k)
        for _ in range(primitive.max_primitives):
            choice = agent.choose(obs)
            before, error_before = quat_wxyz_to_matrix(env.object_pose()[3:]), \
                env.rotation_to_goal()
            obs, _, terminated, truncated, _ = env.step({"point": choice["point"],
                                                         "motion": choice["motion"]})
            total += 1
            after = quat_wxyz_to_matrix(env.object_pose()[3:])
            if up_angle(after, before) > TIPPED_ANGLE_RAD:
                tipping[o.object_id] += 1
            else:
                turns.append(rotation_angle(after @ before.T))
                before_errors.append(error_before)
                after_errors.append(env.rotation_to_goal())
            if terminated or truncated:
                break
    count = sum(tipping.values())
    print(json.dumps({"run": args.run, "task": args.task, "episodes": args.episodes,
                      "executor_settings": args.set, "primitives": total, "tipping": count,
                      "tipping_share": round(count / max(total, 1), 3),
                      "tipping_by_object": dict(tipping.most_common()),
                      "turn": turn_figures(turns, before_errors, after_errors)}, indent=1))


def turn_figures(turns, before, after, near: bool = True) -> dict:
    """What the primitives that do not tip do to the object's rotation: how far they turn it
    (median, and the share beyond 0.25 rad, the success tolerance), the share that leaves it
    further from the goal's orientation, and the rotation error before and after (median).
    `near`: the same figures again for the primitives that start within 0.6 rad of the goal's
    orientation (push_turn's largest goal turn: the object not yet tipped or spun away)."""
    turns, before, after = (np.asarray(x, float) for x in (turns, before, after))
    if not len(turns):
        return {"primitives": 0}
    figures = {"primitives": int(len(turns)),
            "median_turn_rad": round(float(np.median(turns)), 3),
            "share_turning_over_0.25_rad": round(float((turns > 0.25).mean()), 3),
            "share_leaving_it_further_from_the_goal": round(float((after > before).mean()), 3),
            "median_error_before_rad": round(float(np.median(before)), 3),
            "median_error_after_rad": round(float(np.median(after)), 3)}
    if near:
        close = before <= 0.6
        figures["starting_within_0.6_rad"] = turn_figures(turns[close], before[close],
                                                          after[close], near=False)
    return figures


if __name__ == "__main__":
    np.set_printoptions(precision=3)
    main()
