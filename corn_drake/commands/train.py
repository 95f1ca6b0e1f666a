"""`corn-drake train`: PPO for the teacher policy (see corn_drake/rl/trainer.py).

OUT is locked while the command runs (a second `train` into it refuses). Training into an
existing run resumes it, and only with the arguments it was started with (compared with its
config.yaml, before anything is written): --steps may grow, --ray-address and --no-progress
may change; any other difference is refused, naming the argument and both values.
"""

from __future__ import annotations

from pathlib import Path

from corn_drake.cli_types import finite_float, nonnegative_int, positive_int

NAME = "train"
HELP = "train a teacher policy with PPO (resumes from OUT/checkpoints/last.pt)"


def add_arguments(parser):
    parser.add_argument("--policy", choices=("corn", "e2e", "state", "pn"), default="state")
    parser.add_argument("--objects", default="", help="object library folder (default: the YAML's object)")
    parser.add_argument("--encoder", default="", help="pretrained encoder checkpoint (corn, pn)")
    parser.add_argument("--allow-weak-encoder", action="store_true",
                        help="accept an --encoder whose pretraining contact F1 is below 0.8 "
                             "(or unrecorded), with a warning")
    parser.add_argument("--steps", type=positive_int, default=20_000,
                        help="total environment steps")
    parser.add_argument("--workers", type=nonnegative_int, default=0,
                        help="Ray rollout workers (0: in-process)")
    parser.add_argument("--envs-per-worker", type=positive_int, default=4)
    parser.add_argument("--rollout-steps", type=positive_int, default=32)
    parser.add_argument("--minibatches", type=positive_int, default=4,
                        help="PPO minibatches per epoch")
    parser.add_argument("--init-log-std", type=finite_float, default=0.0,
                        help="initial log-std of the Gaussian policy (paper: 0)")
    parser.add_argument("--ppo", action="append", default=[], metavar="NAME=VALUE",
                        help="override a PPOConfig field, e.g. --ppo lr=1e-4 (repeatable)")
    parser.add_argument("--episode-steps", type=positive_int, default=None,
                        help="override the YAML's step limit")
    parser.add_argument("--config", default=None, help="teacher diagram YAML")
    parser.add_argument("--ray-address", default="", help="connect to a Ray cluster instead of a local one")
    parser.add_argument("--seed", type=nonnegative_int, default=0)
    parser.add_argument("--out", required=True, help="run folder, e.g. runs/NAME")
    parser.add_argument("--no-progress", action="store_true")


def run(args) -> int:
    from corn_drake.diagrams import load_teacher_config
    from corn_drake.rl.encoders import load_encoder
    from corn_drake.config import TrainConfig
    from corn_drake.rl.trainer import Trainer, save_config
    from corn_drake.run_folder import lock_folder, refuse_changed_config

    env_cfg = load_teacher_config(args.config)
    if args.episode_steps:
        env_cfg.task.episode_steps = args.episode_steps
    if args.objects:  # every train object of the library: each env takes a new one every episode
        env_cfg.scene.object.kind = "library"
        env_cfg.scene.object.library = args.objects
        env_cfg.scene.object.object_id = ""
    if env_cfg.scene.object.kind == "library" and not env_cfg.scene.object.object_id:
        from corn_drake.rl.vec_env import library_train_ids

        library_train_ids(env_cfg.scene.object.library)  # a bad library fails before any write
    cfg = TrainConfig(policy=args.policy, total_steps=args.steps, workers=args.workers,
                      envs_per_worker=args.envs_per_worker, rollout_steps=args.rollout_steps,
                      seed=args.seed, ray_address=args.ray_address, encoder=args.encoder,
                      init_log_std=args.init_log_std, allow_weak_encoder=args.allow_weak_encoder,
                      env=env_cfg)
    cfg.ppo.minibatches = args.minibatches
    cfg.ppo = ppo_overrides(cfg.ppo, args.ppo)
    out = Path(args.out)
    with lock_folder(out):
        # Everything that can refuse comes before the first write: a refused resume leaves the
        # run as it was (its config.yaml is what `evaluate` rebuilds the policy from).
        refuse_changed_config(out, out / "config.yaml", cfg, may_grow=RESUME_MAY_GROW,
                              ignore=RESUME_MAY_CHANGE, name=argument_of_field)
        encoder = load_encoder(cfg.policy, cfg.encoder, cfg.allow_weak_encoder)
        trainer = Trainer(cfg, out, encoder)  # reads (and checks) the checkpoint, writes nothing
        save_config(cfg, out / "config.yaml")
        metrics = trainer.train(progress=not args.no_progress)
    print(f"trained {metrics['global_step']} steps; run folder {out}")
    return 0


# A resumed run (OUT holds config.yaml) must be given the arguments it was started with, except
# these config fields: --steps may grow (extends the run); --ray-address only says where the
# workers run; checkpoint_every is not an output. --no-progress is not in the config at all.
RESUME_MAY_GROW = ("total_steps",)
RESUME_MAY_CHANGE = ("ray_address", "checkpoint_every")
# The argument that sets each config field, to name it when a resume differs.
_FIELD_ARGUMENTS = {"policy": "--policy", "total_steps": "--steps", "workers": "--workers",
                    "envs_per_worker": "--envs-per-worker", "rollout_steps": "--rollout-steps",
                    "seed": "--seed", "encoder": "--encoder", "init_log_std": "--init-log-std",
                    "allow_weak_encoder": "--allow-weak-encoder",
                    "ppo.minibatches": "--minibatches",
                    "env.task.episode_steps": "--episode-steps (or --config task.episode_steps)"}


def argument_of_field(field: str) -> str:
    """The train argument behind a TrainConfig field ('a.b.c'), for refusal messages."""
    if field in _FIELD_ARGUMENTS:
        return _FIELD_ARGUMENTS[field]
    if field.startswith("env.scene.object."):
        return f"--objects (or --config scene.object.{field.rsplit('.', 1)[1]})"
    if field.startswith("ppo."):
        return f"--ppo {field[4:]}"
    if field.startswith("env."):
        return f"--config ({field[4:]})"
    return field


def ppo_overrides(ppo, items: list[str]):
    """PPOConfig with `NAME=VALUE` overrides; an unknown name or a bad value is named."""
    import dataclasses

    from corn_drake.errors import InputError

    fields = {f.name: f for f in dataclasses.fields(ppo)}
    changes = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or name not in fields:
            raise InputError(f"--ppo {item!r}: expected NAME=VALUE with NAME one of {sorted(fields)}")
        kind = type(getattr(ppo, name))
        try:
            changes[name] = kind(value)
        except ValueError:
            raise InputError(f"--ppo {item!r}: {value!r} is not a {kind.__name__}") from None
    return dataclasses.replace(ppo, **changes)
