"""`corn-drake bench policies`: training steps/s of each teacher policy, in one run, on one scene.

The paper compares the representations at equal wall-clock as well as at equal steps. What a
policy adds to a training step is its encoder's inference and its part of the PPO update
(`e2e` trains the patch encoder through every epoch, `pn` runs a 1024-wide MLP over every
point, `state` has no encoder); the envs and physics are the same for all. So the real trainer
(bench/training/timed_training.py: randomly initialised encoders, timing only) trains each policy in turn
on the same task, envs and seed (`--objects`: the library's train objects, the envs starting
on the same objects for every policy), and the report gives each policy's `train_steps_per_s`
and its ratio to the first policy's, measured minutes apart on the same machine. Training runs
that shared their core for a while record slower rates than a quiet machine gives; `corn-drake
curves --x hours --rates REPORT` charges every run's steps at its policy's rate here instead.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses

from corn_drake.arguments.renamed import add_renamed
from corn_drake.arguments.value_types import nonnegative_int, positive_int
from corn_drake.arguments.torch_threads import add_torch_threads_argument
from corn_drake.rl.policy_kinds import POLICY_KINDS

NAME = "policies"
HELP = "training steps/s of each teacher policy (same run, same envs)"


def policy_list(text: str) -> list[str]:
    names = [t.strip() for t in text.split(",") if t.strip()]
    bad = [n for n in names if n not in POLICY_KINDS]
    if not names or bad or len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(
            f"a comma-separated list of distinct policies from {', '.join(POLICY_KINDS)}, got {text!r}")
    return names


def add_arguments(parser):
    parser.add_argument("--policies", type=policy_list, default=",".join(POLICY_KINDS),
                        help="comma-separated, the first is the reference")
    parser.add_argument("--task", default="push",
                        help="task overlay: a name in diagrams/tasks/ or a YAML file")
    parser.add_argument("--objects", default="",
                        help="object library: the envs cycle its train objects, as `train "
                             "--objects` (default: the task's own object)")
    parser.add_argument("--envs-per-worker", type=positive_int, default=32,
                        help="envs, stepped in this process (as `train --workers 0 "
                             "--envs-per-worker N`)")
    add_renamed(parser, "--envs", "--envs-per-worker", " (as in `train`)")
    parser.add_argument("--updates", type=positive_int, default=3, help="PPO updates timed")
    parser.add_argument("--warmup-updates", type=nonnegative_int, default=1,
                        help="PPO updates run first, untimed")
    parser.add_argument("--rollout-steps", type=positive_int, default=32,
                        help="policy steps per env and update")
    parser.add_argument("--seed", type=nonnegative_int, default=0,
                        help="seed of the networks and the envs' episodes")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", dest="set",
                        help="a PPO setting of the runs being timed, e.g. --set "
                             "ppo.separate_critic=false (repeatable; ppo.* only: the update's "
                             "cost depends on them, the envs' does not; default: none)")
    add_torch_threads_argument(parser, "every policy, as `train` takes it")


def run(args) -> dict:
    import torch

    from corn_drake.bench.phases import PhaseTimer
    from corn_drake.bench.training.timed_training import check_counts, run_trainer, train_config
    from corn_drake.config.training import TrainConfig
    from corn_drake.nn.threads import torch_threads
    from corn_drake.config.plumbing.overrides import apply_sets, on_library
    from corn_drake.config.plumbing.diagram_files import load_teacher_config

    env_cfg = load_teacher_config(args.task)
    if args.objects:
        from corn_drake.rl.envs.vec_env import library_train_ids

        library_train_ids(args.objects)  # a library that cannot be cycled is named here
        env_cfg = on_library(TrainConfig(env=env_cfg), args.objects).env
    env_cfg.check()
    # Parsed once, before any env is built (a bad --set fails here); every run gets a copy.
    ppo = apply_sets(TrainConfig(), args.set, only="ppo").ppo
    steps = args.envs_per_worker * args.rollout_steps * args.updates  # timed, per policy
    rates = {}
    with torch_threads(args.torch_threads):
        threads_used = torch.get_num_threads()
        for policy in args.policies:
            cfg = dataclasses.replace(
                train_config(argparse.Namespace(**{**vars(args), "policy": policy}), env_cfg,
                             workers=0, envs_per_worker=args.envs_per_worker),
                ppo=copy.deepcopy(ppo))
            timer = PhaseTimer()
            run_trainer(cfg, timer, args.warmup_updates)
            check_counts(timer, {timer.WINDOW: args.updates})
            rates[policy] = steps / timer.window_seconds
            print(f"{policy}: {rates[policy]:.1f} training steps/s")
    reference = args.policies[0]
    return {
        "train_steps_per_s": rates,
        "relative_to_reference": {p: r / rates[reference] for p, r in rates.items()},
        "reference": reference,
        "task": env_cfg.task.name,
        "objects": args.objects or env_cfg.scene.object.kind,
        "envs": args.envs_per_worker, "updates": args.updates, "warmup_updates": args.warmup_updates,
        "rollout_steps": args.rollout_steps, "steps_per_policy": steps,
        "torch_threads": threads_used, "ppo_sets": list(args.set),
    }
