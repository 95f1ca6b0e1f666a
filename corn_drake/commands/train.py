"""`corn-drake train`: PPO for the teacher policy (see corn_drake/rl/trainer.py)."""

from __future__ import annotations

from pathlib import Path

NAME = "train"
HELP = "train a teacher policy with PPO (resumes from OUT/checkpoints/last.pt)"


def add_arguments(parser):
    parser.add_argument("--policy", choices=("corn", "e2e", "state", "pn"), default="state")
    parser.add_argument("--objects", default="", help="object library folder (default: the YAML's object)")
    parser.add_argument("--encoder", default="", help="pretrained encoder checkpoint (corn, pn)")
    parser.add_argument("--steps", type=int, default=20_000, help="total environment steps")
    parser.add_argument("--workers", type=int, default=0, help="Ray rollout workers (0: in-process)")
    parser.add_argument("--envs-per-worker", type=int, default=4)
    parser.add_argument("--rollout-steps", type=int, default=32)
    parser.add_argument("--minibatches", type=int, default=4, help="PPO minibatches per epoch")
    parser.add_argument("--init-log-std", type=float, default=0.0,
                        help="initial log-std of the Gaussian policy (paper: 0)")
    parser.add_argument("--ppo", action="append", default=[], metavar="NAME=VALUE",
                        help="override a PPOConfig field, e.g. --ppo lr=1e-4 (repeatable)")
    parser.add_argument("--episode-steps", type=int, default=None, help="override the YAML's step limit")
    parser.add_argument("--config", default=None, help="teacher diagram YAML")
    parser.add_argument("--ray-address", default="", help="connect to a Ray cluster instead of a local one")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", required=True, help="run folder, e.g. runs/NAME")
    parser.add_argument("--no-progress", action="store_true")


def run(args) -> int:
    from corn_drake.diagrams import load_teacher_config
    from corn_drake.rl.encoders import load_encoder
    from corn_drake.config import TrainConfig
    from corn_drake.rl.trainer import Trainer, save_config

    env_cfg = load_teacher_config(args.config)
    if args.episode_steps:
        env_cfg.task.episode_steps = args.episode_steps
    if args.objects:  # every train object of the library: each env takes a new one every episode
        env_cfg.scene.object.kind = "library"
        env_cfg.scene.object.library = args.objects
        env_cfg.scene.object.object_id = ""
    cfg = TrainConfig(policy=args.policy, total_steps=args.steps, workers=args.workers,
                      envs_per_worker=args.envs_per_worker, rollout_steps=args.rollout_steps,
                      seed=args.seed, ray_address=args.ray_address, encoder=args.encoder,
                      init_log_std=args.init_log_std, env=env_cfg)
    cfg.ppo.minibatches = args.minibatches
    cfg.ppo = ppo_overrides(cfg.ppo, args.ppo)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    save_config(cfg, out / "config.yaml")
    encoder = load_encoder(cfg.policy, cfg.encoder)
    metrics = Trainer(cfg, out, encoder).train(progress=not args.no_progress)
    print(f"trained {metrics['global_step']} steps; run folder {out}")
    return 0


def ppo_overrides(ppo, items: list[str]):
    """PPOConfig with `NAME=VALUE` overrides; an unknown name or a bad value is named."""
    import dataclasses

    fields = {f.name: f for f in dataclasses.fields(ppo)}
    changes = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or name not in fields:
            raise ValueError(f"--ppo {item!r}: expected NAME=VALUE with NAME one of {sorted(fields)}")
        kind = type(getattr(ppo, name))
        try:
            changes[name] = kind(value)
        except ValueError:
            raise ValueError(f"--ppo {item!r}: {value!r} is not a {kind.__name__}") from None
    return dataclasses.replace(ppo, **changes)
