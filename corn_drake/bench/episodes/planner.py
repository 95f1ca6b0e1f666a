"""`corn-drake bench planner`: how many primitives the 6D expert simulates per CPU second, against
bare physics of the very same primitives in the same run.

The expert's labels are what a learned 6D policy is fitted to, so its cost per label matters as
much as its success. Measured on one env (the task's own object, or the first --split object of
--objects), after one untimed decision:
- search: `--decisions` decisions of the expert (rl/planner/search.py, with `--set planner.*`),
  process time, so everything it pays counts: proposing (the policy source's forward pass per
  expanded state), restoring, simulating, snapshotting after every primitive, scoring;
- baseline: every primitive the timed search simulated, replayed from the same start state
  (restore, then the env's step: the primitive's physics and the observation it returns), with
  nothing else: no proposals, no snapshots.
`search_to_bare` is the search's CPU seconds per simulated primitive over the baseline's (the
issue's goal: <= 1.3). Both are process time of this one process: per core.

Imports of numpy, torch and Drake stay inside the functions: `corn-drake bench` imports every
module here to build its parser (tests/test_cli_startup.py).
"""

from __future__ import annotations

import time

from corn_drake.arguments.value_types import nonnegative_int, positive_int

NAME = "planner"
HELP = ("the 6D expert's simulated primitives per CPU second against bare physics of the same "
        "primitives (same run)")


def add_arguments(parser):
    parser.add_argument("--task", default="full6d",
                        help="task overlay: a name in diagrams/tasks/ or a YAML file")
    parser.add_argument("--objects", default="",
                        help="object library: its first --split object (default: the task's own "
                             "box)")
    parser.add_argument("--split", default="unseen", choices=("train", "unseen", "all"),
                        help="which objects of --objects the first is taken from (default "
                             "unseen)")
    parser.add_argument("--decisions", type=positive_int, default=3,
                        help="expert decisions timed (each ~150 simulated primitives at the "
                             "default settings)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", dest="set",
                        help="planner.*, primitive.* or env settings, as `evaluate --run "
                             "planner` takes them (default: none, the calibrated expert's)")
    parser.add_argument("--seed", type=nonnegative_int, default=0, help="the episode's seed")


def _recording_planner(policy, task):
    """The expert's Planner that keeps every expansion it made: (start snapshot, candidates)."""
    from corn_drake.rl.planner.search import Planner
    from corn_drake.rl.planner.sources import make_sources

    class Recording(Planner):
        def _expand(self, env, start, obs):
            branches = super()._expand(env, start, obs)
            self.expansions.append((start, [b.candidate for b in branches]))
            return branches

    planner = Recording(policy.config, make_sources(policy.config, policy.primitive, task))
    planner.expansions = []
    return planner


def _object_spec(args):
    if not args.objects:
        return None
    from corn_drake.assets.library import list_objects, load_object_spec
    from corn_drake.errors import InputError

    ids = list_objects(args.objects, None if args.split == "all" else args.split)
    if not ids:
        raise InputError(f"--objects {args.objects}: no {args.split} objects")
    return load_object_spec(args.objects, ids[0])


def time_search(env, planner, seed: int, decisions: int) -> dict:
    """One untimed decision, then `decisions` timed ones (a new episode where one ends)."""
    obs, _ = env.reset(seed=seed)
    planner.reset(seed)
    obs, _, terminated, truncated, _ = planner.act(env, obs)
    planner.expansions.clear()
    seconds = simulated = 0.0
    for _ in range(decisions):
        if terminated or truncated:
            seed += 1
            obs, _ = env.reset(seed=seed)
            planner.reset(seed)
        started = time.process_time()
        obs, _, terminated, truncated, info = planner.act(env, obs)
        seconds += time.process_time() - started
        simulated += info["planner"]["simulated"]
    return {"seconds": seconds, "simulated": int(simulated)}


def time_bare(env, expansions) -> dict:
    """Every recorded primitive again from its start state: restore and the env's step only."""
    seconds, count = 0.0, 0
    for start, candidates in expansions:
        for candidate in candidates:
            started = time.process_time()
            env.restore(start)
            env.step(candidate.action(), aim=candidate.aim)
            seconds += time.process_time() - started
            count += 1
    return {"seconds": seconds, "simulated": count}


def run(args) -> dict:
    from corn_drake.rl.envs.primitive_env import PrimitiveEnv
    from corn_drake.rl.runs.kinds import load_any_run

    loaded = load_any_run("planner")
    run_cfg, _ = loaded.configure(args.task, args.set)
    policy = loaded.agent
    env = PrimitiveEnv(run_cfg.env, policy.primitive, _object_spec(args))
    planner = _recording_planner(policy, run_cfg.env.task)
    search = time_search(env, planner, args.seed, args.decisions)
    bare = time_bare(env, planner.expansions)
    if bare["simulated"] != search["simulated"]:
        raise RuntimeError(f"replayed {bare['simulated']} primitives of {search['simulated']}")
    per_search = search["seconds"] / search["simulated"]
    per_bare = bare["seconds"] / bare["simulated"]
    print(f"planner: {1 / per_search:.2f} simulated primitives per CPU s; bare physics of the "
          f"same primitives {1 / per_bare:.2f}; search / bare {per_search / per_bare:.2f}")
    return {
        "search_primitives_per_cpu_s": 1 / per_search,
        "bare_primitives_per_cpu_s": 1 / per_bare,
        "search_to_bare": per_search / per_bare,
        "simulated_per_decision": search["simulated"] / args.decisions,
        "cpu_seconds_per_decision": search["seconds"] / args.decisions,
        "decisions_per_core_hour": 3600 * args.decisions / search["seconds"],
        "simulated": search["simulated"],
        "reference": "bare physics: the same primitives replayed from their start states "
                     "(restore + the env's step), nothing else",
        "task": run_cfg.env.task.name, "object": env.scene.object_spec.name,
        "planner": policy.describe()["planner"], "decisions": args.decisions,
        "seed": args.seed,
    }
