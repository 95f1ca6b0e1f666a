"""How often a primitive policy's single primitives tip or roll the object, on push_turn's unseen
episodes: the measurement behind README.md's item 9 ("Why objects tip").

    .venv/bin/python docs/results/primitive/tipping_per_primitive.py models/weights/push_primitive \
        --episodes 23
    .venv/bin/python docs/results/primitive/tipping_per_primitive.py models/weights/push_primitive \
        --episodes 46 --set push_height=0.02 --set finger_tilt_deg=30 --set approach_steps=30

Episode k runs on the library's k-th unseen object (round-robin) with seed 1000 + k, the policy
acting greedily from outside the diagram (PrimitiveEnv.step, one primitive per step). A primitive
"tips" when the object's up axis turns more than 0.5 rad during it (the failure table's rule,
evaluation/failures.py). Prints one JSON object: primitives, tipping, their share, tipping
primitives per object.
"""

from __future__ import annotations

import argparse
import collections
import json

import numpy as np

from corn_drake.assets.manifest import read_manifest
from corn_drake.config.diagram_files import load_primitive_env_config
from corn_drake.rl.primitive_agent import load_primitive_run
from corn_drake.rl.primitive_env import PrimitiveEnv
from corn_drake.tasks.faces import TIPPED_ANGLE_RAD
from corn_drake.transforms import quat_wxyz_to_matrix, up_angle


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
    for k in range(args.episodes):
        cfg = load_primitive_env_config(args.task)
        o = cfg.scene.object
        o.kind, o.library, o.object_id = "library", args.objects, unseen[k % len(unseen)]
        env = PrimitiveEnv(cfg, primitive)
        obs, _ = env.reset(seed=1000 + k)
        for _ in range(primitive.max_primitives):
            choice = agent.choose(obs)
            before = quat_wxyz_to_matrix(env.object_pose()[3:])
            obs, _, terminated, truncated, _ = env.step({"point": choice["point"],
                                                         "motion": choice["motion"]})
            total += 1
            if up_angle(quat_wxyz_to_matrix(env.object_pose()[3:]), before) > TIPPED_ANGLE_RAD:
                tipping[o.object_id] += 1
            if terminated or truncated:
                break
    count = sum(tipping.values())
    print(json.dumps({"run": args.run, "task": args.task, "episodes": args.episodes,
                      "executor_settings": args.set, "primitives": total, "tipping": count,
                      "tipping_share": round(count / max(total, 1), 3),
                      "tipping_by_object": dict(tipping.most_common())}, indent=1))


if __name__ == "__main__":
    np.set_printoptions(precision=3)
    main()
