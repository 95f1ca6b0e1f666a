"""Where in a primitive the object tips or rolls: README.md's item 38.

    .venv/bin/python docs/results/primitive/tilt_phases.py models/weights/full6d_outcome \
        --task push_turn --set primitive.max_primitives=10 --family bottle \
        --out docs/results/primitive/tilt_phases_bottle.json

One episode per unseen object of `--family` (seed 100 + its index, not an evaluation seed), the
run choosing as `evaluate` would. Every policy period the executor's phase and the object's box
keypoints are logged (by wrapping PrimitivePlanner.plan, which sees both); per primitive, the
up direction's turn since it began (systems/primitive_executor.up_turn). Reported: the turn
gained within each phase (between a tick and the next, the phase the first one commanded in,
as its memory said before planning: a primitive's first tick says idle), summed over all
primitives, and for each primitive that turned the object past 20 degrees, the phase in which
it first passed 10, with the chosen point's normal, its height above the object's lowest
point and the motion.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
from pathlib import Path

import numpy as np

from corn_drake.assets.library import list_objects, load_object_spec
from corn_drake.config.diagram_files import primitive_run_on
from corn_drake.rl.primitive.agent import load_primitive_run
from corn_drake.rl.envs.primitive_env import PrimitiveEnv
from corn_drake.storage.atomic_files import write_json
from corn_drake.systems import primitive_executor as executor

TIPPED_DEG, FIRST_DEG = 20.0, 10.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--objects", default="data/library_unseen")
    parser.add_argument("--family", required=True, help="object id prefix, e.g. bottle")
    parser.add_argument("--task", default=None)
    parser.add_argument("--set", action="append", default=[], dest="set")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    base, agent, _ = load_primitive_run(args.run)
    cfg = primitive_run_on(base, args.task, args.set)
    agent.primitive_config, agent.task = cfg.primitive, cfg.env.task
    ticks = []  # (phase before the tick, keypoints seen at it) of the primitive running
    plan = executor.PrimitivePlanner.plan

    def logged(self, memory, tool_p, tool_R, top_z, primitive, object_xy=None, keypoints=None):
        ticks.append((int(memory[0]), np.array(keypoints, float)))
        return plan(self, memory, tool_p, tool_R, top_z, primitive, object_xy, keypoints)

    executor.PrimitivePlanner.plan = logged
    objects = [o for o in list_objects(args.objects, "unseen") if o.startswith(args.family)]
    if not objects:
        raise SystemExit(f"--family {args.family}: no unseen object of {args.objects} starts so")
    gained, tips = collections.Counter(), []
    for k, object_id in enumerate(objects):
        env = PrimitiveEnv(dataclasses.replace(cfg.env, seed=0), cfg.primitive,
                           load_object_spec(args.objects, object_id))
        obs, _ = env.reset(seed=100 + k)
        for _ in range(cfg.primitive.max_primitives):
            ticks.clear()
            choice = agent.choose(obs)
            cloud, normals = obs["cloud"], obs["normals"]
            chosen = {"object": object_id, "normal_z": float(normals[choice["point"]][2]),
                      "point_height_m": float(cloud[choice["point"], 2] - cloud[:, 2].min()),
                      "object_height_m": float(np.ptp(cloud[:, 2])),
                      "motion": np.round(choice["motion"], 3).tolist()}
            obs, _, done, cut, _ = env.step({"point": choice["point"], "motion": choice["motion"]})
            start = ticks[0][1]
            # The turn between two ticks is the doing of the first one's command.
            for (phase, before), (_, after) in zip(ticks, ticks[1:]):
                gained[executor.PHASES[phase]] += np.rad2deg(executor.up_turn(before, after))
            turns = [np.rad2deg(executor.up_turn(start, kp)) for _, kp in ticks]
            if turns[-1] > TIPPED_DEG:
                # The keypoints of tick i show what the command of tick i - 1 did.
                first = next(i for i, t in enumerate(turns) if t > FIRST_DEG)
                tips.append({**chosen, "phase": executor.PHASES[ticks[first - 1][0]],
                             "turn_deg": round(turns[-1], 1)})
            if done or cut:
                break
        print(f"{object_id}: {len(tips)} tips so far", flush=True)
    report = {"run": str(args.run), "family": args.family, "objects": objects,
              "turn_gained_per_phase_deg": {k: round(v, 1) for k, v in gained.items()},
              "tips_by_phase": dict(collections.Counter(t["phase"] for t in tips)),
              "tips": tips}
    write_json(args.out, report)
    print(report["turn_gained_per_phase_deg"], report["tips_by_phase"])


if __name__ == "__main__":
    main()
