"""`corn-drake train`: the teacher policy, with PPO (corn_drake/rl/training/ppo_trainer.py) or, for
`--policy primitive`, TD3 (corn_drake/commands/learning/train_primitive.py).

A new run's config is built in layers (corn_drake/config/plumbing/diagram_files.py and overrides.py):
the base diagram, the `--task` overlay, then the shortcut flags and `--set KEY=VALUE`
overrides; the result is written into OUT/config.yaml. Training into an existing run resumes it
from that file: `--out` is all it needs (`--resume` makes that a requirement, so a mistyped
folder is not a new run). An argument given on a resume is an override of the recorded config,
checked before anything is written: --steps may grow, --ray-address and --device (and
checkpoint_every, snapshot_every) may change; any other difference is refused, naming the
argument and both values. What an accepted override changes is printed.

OUT is locked while the command runs (a second `train` into it refuses); the start-or-resume
flow is run_folders/resumable.py's, shared with `distill`.
"""

from __future__ import annotations


from corn_drake.arguments.run_flags import (RESUME_MAY_CHANGE, RUN_SHORTCUTS, add_run_arguments,
                                            flag_of_field)
from corn_drake.arguments.torch_threads import add_torch_threads_argument
from corn_drake.arguments.value_types import finite_float, positive_int
from corn_drake.rl.policy_kinds import FROZEN_ENCODER_POLICIES, TRAIN_POLICIES

NAME = "train"
HELP = ("train a teacher policy: PPO for --policy corn (default), state, e2e, pn, p2v-lite, rot; "
        "TD3 for --policy primitive (resumes from OUT/checkpoints/last.pt)")
# A new run's policy when --policy is not given: CORN, the method the project rebuilds.
DEFAULT_POLICY = "corn"

# The shortcut flags: argparse dest -> the TrainConfig field it sets (the run settings' shared
# flags, then train's own). They default to None: a new run takes the field's default, a
# resumed run its recorded value.
SHORTCUTS = {**RUN_SHORTCUTS, "policy": "policy", "rollout_steps": "rollout_steps",
             "minibatches": "ppo.minibatches", "init_log_std": "init_log_std",
             "init_from": "init_from"}
# A resumed run may change only these config fields: total_steps may grow (extends the run);
# where the run executes and how often it checkpoints or snapshots are not outputs.
RESUME_MAY_GROW = ("total_steps",)
RESUME_MAY_CHANGE = (*RESUME_MAY_CHANGE, "snapshot_every")


def add_arguments(parser):
    add_run_arguments(parser, NAME, encoder_help="pretrained encoder file of the kind the policy "
                                                 "names, needed by corn (the default policy), pn, "
                                                 "p2v-lite and rot: e.g. `corn-drake pretrain`'s "
                                                 "OUT/encoder.pt or the shipped models/weights/"
                                                 "push_corn/encoder.pt (default: none; a resumed "
                                                 "run's recorded one)")
    parser.add_argument("--task", default=None,
                        help="task overlay: a name in diagrams/tasks/ or a YAML file "
                             "(default: the base diagram, the paper's 6D task)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", dest="set",
                        help="override a config field, e.g. --set ppo.lr=1e-4 or --set "
                             "task.episode_steps=50 (repeatable; KEY a TrainConfig field, the "
                             "env's sections scene/randomization/controller/task without env.; "
                             "default: none)")
    parser.add_argument("--policy", choices=TRAIN_POLICIES, default=None,
                        help="the teacher's policy and with it the algorithm: PPO trains corn, "
                             "state, e2e, pn, p2v-lite and rot (the variants: "
                             "corn_drake/rl/policy_kinds.py); TD3 trains primitive, the "
                             "contact-primitive policy (off-policy, "
                             "corn_drake/commands/learning/train_primitive.py); "
                             f"default: {DEFAULT_POLICY} for a new run, the method the project "
                             "is named for, which needs --encoder; a resumed run keeps its own, "
                             "an --init-from run takes its source's)")
    parser.add_argument("--objects", default=None,
                        help="object library folder: train on all its train objects "
                             "(default: the task's object)")
    parser.add_argument("--init-from", default=None, metavar="RUN",
                        help="start from this finished run's trained agent (a curriculum, e.g. "
                             "push -> push_turn): its policy and encoder unless given, a fresh "
                             "optimiser and step count (default: none, a fresh agent)")
    parser.add_argument("--rollout-steps", type=positive_int, default=None,
                        help="policy steps per env between PPO updates (default: 32)")
    parser.add_argument("--minibatches", type=positive_int, default=None,
                        help="PPO minibatches per epoch (default: 1, the authors' code)")
    parser.add_argument("--init-log-std", type=finite_float, default=None,
                        help="initial log-std of the Gaussian policy (default: the paper's 0)")
    add_torch_threads_argument(parser, "the agent's inference and PPO updates (not recorded "
                                       "in the run: it changes the speed, not the results)")


def requested_config(args, recorded):
    """The TrainConfig `args` ask for: on top of the run's `recorded` config (None: a new run,
    on top of the defaults and the base diagram), the layers in order: --task, the shortcut
    flags, --set. Repeating a run's original arguments gives its recorded config again."""
    from corn_drake.config.training import TrainConfig
    from corn_drake.config.plumbing.overrides import apply_sets, on_library, set_fields
    from corn_drake.config.plumbing.diagram_files import load_teacher_config, replace_task

    if recorded is None:
        cfg = TrainConfig(env=load_teacher_config(args.task))
        if args.policy is None and args.init_from is None:  # --init-from takes its source's
            cfg = set_fields(cfg, {"policy": DEFAULT_POLICY}, "--policy")
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
    from corn_drake.commands.learning import train_primitive

    if train_primitive.wants_primitive(args):
        return train_primitive.run(args)
    from corn_drake.config.training import TrainConfig
    from corn_drake.nn.threads import torch_threads
    from corn_drake.rl.pretrained_encoders import load_encoder
    from corn_drake.rl.training.ppo_trainer import Trainer
    from corn_drake.run_folders.resumable import ResumableRun

    def check_new():  # a new run's own argument errors, named before a folder it cannot take
        checked_config(requested_config(args, None), args, new_run=True)

    with ResumableRun.open(args.out, TrainConfig, resume_required=args.resume,
                           check_new=check_new) as run_folder:
        cfg = checked_config(requested_config(args, run_folder.recorded), args,
                             new_run=run_folder.is_new)
        run_folder.refuse_changes(cfg, may_grow=RESUME_MAY_GROW, may_change=RESUME_MAY_CHANGE,
                                  name=argument_of_field)
        encoder = load_encoder(cfg.policy, cfg.encoder, cfg.allow_weak_encoder)
        trainer = Trainer(cfg, run_folder.out, encoder)  # reads the checkpoint, writes nothing
        run_folder.write_config(cfg, f"task {cfg.env.task.name}, policy {cfg.policy}, "
                                     f"{cfg.total_steps} steps")
        with torch_threads(args.torch_threads):
            metrics = trainer.train(progress=not args.no_progress)
    print(f"trained {metrics['global_step']} steps; run folder {run_folder.out}")
    return 0


def checked_config(cfg, args, new_run: bool):
    """`cfg` refused for anything no run can start with, before any write: a library with a
    broken object, a value out of its bounds, an --init-from source that does not fit, a device
    this machine lacks. A new run from --init-from takes the source's policy and encoder."""
    from corn_drake.rl.device import training_device

    if cfg.env.scene.object.cycles_library:
        from corn_drake.rl.envs.vec_env import library_train_ids

        library_train_ids(cfg.env.scene.object.library)  # every train object loaded and checked
    check_config(cfg)
    if cfg.init_from and new_run:
        from corn_drake.rl.checkpoints import check_init_source

        cfg = check_init_source(cfg, take_policy=args.policy is None)  # and its encoder
    training_device(cfg.device, argument_of_field("device"))  # e.g. cuda on a CPU machine
    check_encoder_given(cfg, args)
    return cfg


def check_encoder_given(cfg, args) -> None:
    """A policy that reads a frozen pretrained encoder refuses to start without one, saying
    where one comes from (corn is the default policy, so this is a newcomer's first error)."""
    from corn_drake.errors import InputError

    if cfg.policy not in FROZEN_ENCODER_POLICIES or cfg.encoder or cfg.init_from:
        return
    given = "" if args.policy else " (the default)"
    source = ("`corn-drake pretrain --model corn` writes OUT/encoder.pt; the shipped one is "
              "models/weights/push_corn/encoder.pt" if cfg.policy == "corn" else
              "`corn-drake pretrain` writes it")
    raise InputError(f"--policy {cfg.policy}{given} needs --encoder FILE, its pretrained encoder "
                     f"({source}); or choose --policy state (no encoder) or e2e (trains its own)")


def check_config(cfg) -> None:
    """cfg.check() (the bounds every config declares, config/plumbing/bounds.py, and what no episode can
    be built from), its error naming the train argument behind the field it names."""
    from corn_drake.errors import InputError

    try:
        cfg.check()
    except InputError as e:
        field, _, rest = str(e).partition(" ")
        if not rest.startswith("must "):  # a message that names no single field
            raise
        raise InputError(f"{argument_of_field(field)}: {e}") from None


def argument_of_field(field: str) -> str:
    """The train argument behind a TrainConfig field ('a.b.c'), for refusal messages."""
    flag = flag_of_field(field, SHORTCUTS)
    if flag is not None:
        return flag
    if field.startswith("env.scene.object."):
        return f"--objects (or --set {field[4:]})"
    if field.startswith("env."):
        return f"--task or --set {field[4:]}"
    return f"--set {field}"
