"""`corn-drake train`: PPO for the teacher policy (see corn_drake/rl/trainer.py).

A new run's config is built in layers (corn_drake/run_config.py): the base diagram, the
`--task` overlay, then the shortcut flags and `--set KEY=VALUE` overrides; the result is
written into OUT/config.yaml. Training into an existing run resumes it from that file: `--out`
is all it needs (`--resume` makes that a requirement, so a mistyped folder is not a new run).
An argument given on a resume is an override of the recorded config, checked before anything
is written: --steps may grow, --ray-address, --device (and checkpoint_every, snapshot_every) may change; any
other difference is refused, naming the argument and both values. What an accepted override
changes is printed.

OUT is locked while the command runs (a second `train` into it refuses).
"""

from __future__ import annotations

from pathlib import Path

from corn_drake.cli_types import finite_float, nonnegative_int, positive_int
from corn_drake.nn.threads import add_torch_threads_argument
from corn_drake.policy_kinds import POLICY_KINDS

NAME = "train"
HELP = "train a teacher policy with PPO (resumes from OUT/checkpoints/last.pt)"

# The shortcut flags: argparse dest -> the TrainConfig field it sets. They default to None: a
# new run takes the field's default, a resumed run its recorded value.
SHORTCUTS = {"policy": "policy", "steps": "total_steps", "workers": "workers",
             "envs_per_worker": "envs_per_worker", "rollout_steps": "rollout_steps",
             "minibatches": "ppo.minibatches", "init_log_std": "init_log_std",
             "encoder": "encoder", "allow_weak_encoder": "allow_weak_encoder", "seed": "seed",
             "ray_address": "ray_address", "device": "device", "init_from": "init_from"}
# A resumed run may change only these config fields: total_steps may grow (extends the run);
# ray_address only says where the workers run, device where the learner's tensors live
# (checkpoints hold CPU tensors); checkpoint_every and snapshot_every are not outputs.
RESUME_MAY_GROW = ("total_steps",)
RESUME_MAY_CHANGE = ("ray_address", "device", "checkpoint_every", "snapshot_every")


def add_arguments(parser):
    parser.add_argument("--out", required=True,
                        help="run folder, e.g. runs/NAME; an existing run resumes from its "
                             "config.yaml (no other argument needed)")
    parser.add_argument("--resume", action="store_true",
                        help="OUT must be an existing run (refuses to start a new one, e.g. "
                             "on a mistyped folder)")
    parser.add_argument("--task", default=None,
                        help="task overlay: a name in diagrams/tasks/ or a YAML file "
                             "(default: the base diagram, the paper's 6D task)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", dest="set",
                        help="override a config field, e.g. --set ppo.lr=1e-4 or --set "
                             "task.episode_steps=50 (repeatable; KEY a TrainConfig field, the "
                             "env's sections scene/randomization/controller/task without env.)")
    parser.add_argument("--policy", choices=POLICY_KINDS, default=None,
                        help="default: state (the variants: corn_drake/policy_kinds.py)")
    parser.add_argument("--objects", default=None,
                        help="object library folder: train on all its train objects "
                             "(default: the task's object)")
    parser.add_argument("--init-from", default=None, metavar="RUN",
                        help="start from this finished run's trained agent (a curriculum, e.g. "
                             "push -> push_turn): its policy and encoder unless given, a fresh "
                             "optimiser and step count")
    parser.add_argument("--encoder", default=None,
                        help="pretrained encoder checkpoint (corn, pn, p2v-lite, rot), of the "
                             "kind the policy names")
    parser.add_argument("--allow-weak-encoder", action="store_true", default=None,
                        help="accept an --encoder below its pretraining bar (contact F1 0.8; "
                             "pretext skill 0.2) or without a record, with a warning")
    parser.add_argument("--steps", type=positive_int, default=None,
                        help="total environment steps (default: 20000)")
    parser.add_argument("--workers", type=nonnegative_int, default=None,
                        help="Ray rollout workers (default 0: in-process)")
    parser.add_argument("--envs-per-worker", type=positive_int, default=None, help="default: 4")
    parser.add_argument("--rollout-steps", type=positive_int, default=None, help="default: 32")
    parser.add_argument("--minibatches", type=positive_int, default=None,
                        help="PPO minibatches per epoch (default: 1, the authors' code)")
    parser.add_argument("--init-log-std", type=finite_float, default=None,
                        help="initial log-std of the Gaussian policy (default: the paper's 0)")
    parser.add_argument("--ray-address", default=None,
                        help="connect to a Ray cluster instead of a local one")
    parser.add_argument("--seed", type=nonnegative_int, default=None, help="default: 0")
    parser.add_argument("--device", default=None,
                        help="torch device of the agent, its batched inference and the PPO "
                             "update: cpu (default), cuda or cuda:N; the envs run on the CPU")
    add_torch_threads_argument(parser, "the agent's inference and PPO updates (not recorded "
                                       "in the run: it changes the speed, not the results; 1 "
                                       "when another busy process shares a small machine)")
    parser.add_argument("--no-progress", action="store_true")


def requested_config(args, recorded):
    """The TrainConfig `args` ask for: on top of the run's `recorded` config (None: a new run,
    on top of the defaults and the base diagram), the layers in order: --task, the shortcut
    flags, --set. Repeating a run's original arguments gives its recorded config again."""
    from corn_drake.config import TrainConfig
    from corn_drake.run_config import (apply_sets, load_env_config, on_library, replace_task,
                                       set_fields)

    if recorded is None:
        cfg = TrainConfig(env=load_env_config(args.task))
    else:
        cfg = replace_task(recorded, args.task) if args.task is not None else recorded
    for dest, field in SHORTCUTS.items():
        value = getattr(args, dest)
        if value is not None:
            cfg = set_fields(cfg, {field: value}, "--" + dest.replace("_", "-"))
    if args.objects is not None:  # every train object of the library, a new one every episode
        cfg = on_library(cfg, args.objects)
    return apply_sets(cfg, args.set)


def run(args) -> int:
    from corn_drake.errors import InputError
    from corn_drake.nn.threads import torch_threads
    from corn_drake.rl.device import training_device
    from corn_drake.rl.encoders import load_encoder
    from corn_drake.rl.trainer import Trainer
    from corn_drake.run_config import (config_changes, load_run_config, run_config_path,
                                       write_run_config)
    from corn_drake.run_folder import lock_folder, refuse_config_changes

    out = Path(args.out)
    with lock_folder(out):
        # Everything that can refuse comes before the first write: a refused resume leaves the
        # run as it was (its config.yaml is what `evaluate` rebuilds the policy from).
        recorded = load_run_config(out) if run_config_path(out).is_file() else None
        if args.resume and recorded is None:
            raise InputError(f"--resume: {out} holds no run to resume (no "
                             f"{run_config_path(out).name}); leave --resume off to start one")
        cfg = requested_config(args, recorded)
        if cfg.env.scene.object.cycles_library:
            from corn_drake.rl.vec_env import library_train_ids

            library_train_ids(cfg.env.scene.object.library)  # a bad library fails here
        cfg.env.check()  # a value no episode can be built from is refused before any write
        if cfg.init_from and recorded is None:
            from corn_drake.rl.checkpoints import check_init_source

            cfg = check_init_source(cfg, take_policy=args.policy is None)  # and its encoder
        if cfg.snapshot_every < 0:
            raise InputError(f"{argument_of_field('snapshot_every')}: snapshot_every must be >= 0 "
                             f"(env steps between kept checkpoints; 0 keeps none), got "
                             f"{cfg.snapshot_every}")
        training_device(cfg.device, argument_of_field("device"))  # e.g. cuda on a CPU machine
        if recorded is not None:
            refuse_config_changes(out, recorded, cfg, may_grow=RESUME_MAY_GROW,
                                  ignore=RESUME_MAY_CHANGE, name=argument_of_field)
        encoder = load_encoder(cfg.policy, cfg.encoder, cfg.allow_weak_encoder)
        trainer = Trainer(cfg, out, encoder)  # reads (and checks) the checkpoint, writes nothing
        write_run_config(cfg, out)
        if recorded is None:
            print(f"new run {out}: task {cfg.env.task.name}, policy {cfg.policy}, "
                  f"{cfg.total_steps} steps")
        else:
            changes = config_changes(recorded, cfg)
            print(f"resume {out}: " + ("; ".join(map(str, changes)) or "as recorded"))
        with torch_threads(args.torch_threads):
            metrics = trainer.train(progress=not args.no_progress)
    print(f"trained {metrics['global_step']} steps; run folder {out}")
    return 0


def argument_of_field(field: str) -> str:
    """The train argument behind a TrainConfig field ('a.b.c'), for refusal messages."""
    for dest, name in SHORTCUTS.items():
        if name == field:
            return "--" + dest.replace("_", "-")
    if field.startswith("env.scene.object."):
        return f"--objects (or --set {field[4:]})"
    if field.startswith("env."):
        return f"--task or --set {field[4:]}"
    return f"--set {field}"
