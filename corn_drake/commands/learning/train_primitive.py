"""`corn-drake train --policy primitive`: the contact-primitive policy, trained off-policy
(rl/training/primitive_trainer.py). `train` hands a run here when --policy primitive is given or OUT
already holds a primitive run.

A new run's config: PrimitiveTrainConfig with its env built in layers — the base diagram, the
`--task` overlay, the primitive layer (diagrams/primitive_rollout.yaml) — then --objects, the
run flags train shares with distill (--steps counts primitives here), and `--set KEY=VALUE`
(any PrimitiveTrainConfig field: `--set primitive.push_steps=3`, `--set batch_size=128`, the env
sections without `env.`). A resume takes OUT alone; changes follow `train`'s rules.
`--init-from RUN` starts from another primitive run's actor and critic (a curriculum). The PPO
flags (--rollout-steps, --minibatches, --init-log-std) do not apply and are refused.
"""

from __future__ import annotations

from corn_drake.arguments.run_flags import RESUME_MAY_CHANGE, RESUME_MAY_GROW, RUN_SHORTCUTS
from corn_drake.errors import InputError
from corn_drake.rl.policy_kinds import PRIMITIVE_POLICY

PPO_ONLY_FLAGS = ("rollout_steps", "minibatches", "init_log_std")


def wants_primitive(args) -> bool:
    """Whether this `train` call is a primitive run: --policy primitive, or no --policy and OUT
    already recording one."""
    if args.policy is not None:
        return args.policy == PRIMITIVE_POLICY
    from corn_drake.run_folders.config_file import run_config_path, run_kind

    return run_config_path(args.out).is_file() and run_kind(args.out) == "primitive"


def requested_config(args, recorded):
    from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
    from corn_drake.config.plumbing.overrides import apply_sets, on_library, set_fields
    from corn_drake.config.primitive import PrimitiveTrainConfig

    for dest in PPO_ONLY_FLAGS:
        if getattr(args, dest, None) is not None:
            raise InputError(f"--{dest.replace('_', '-')} is a PPO setting; the primitive policy "
                             "is trained off-policy (see --set for its settings, "
                             "corn_drake/config/primitive.py)")
    if recorded is None:
        cfg = PrimitiveTrainConfig(env=load_primitive_env_config(args.task))
    elif args.task is not None:
        env = load_primitive_env_config(args.task)
        env.scene.object = recorded.env.scene.object
        import dataclasses

        cfg = dataclasses.replace(recorded, env=env)
    else:
        cfg = recorded
    for dest, field in RUN_SHORTCUTS.items():
        value = getattr(args, dest)
        if value is not None:
            cfg = set_fields(cfg, {field: value}, "--" + dest.replace("_", "-"))
    if args.objects is not None:
        cfg = on_library(cfg, args.objects)
    if args.init_from is not None:
        cfg = set_fields(cfg, {"init_from": args.init_from}, "--init-from")
    return apply_sets(cfg, args.set)


def checked_config(cfg):
    if cfg.env.scene.object.cycles_library:
        from corn_drake.rl.envs.vec_env import library_train_ids

        library_train_ids(cfg.env.scene.object.library)
    cfg.check()
    if cfg.agent_weights:
        raise InputError(f"agent_weights {cfg.agent_weights!r}: a training run keeps its own "
                         "actor and critic in its checkpoints")
    if cfg.chooser != "critic":
        raise InputError(f"chooser {cfg.chooser!r}: TD3 trains the critic's choice; a run that "
                         "chooses by an outcome model is written by `corn-drake fit-outcome`")
    if cfg.init_from:
        from corn_drake.run_folders.config_file import run_kind

        held = run_kind(cfg.init_from)
        if held != "primitive":
            from corn_drake.run_folders.resumable import KIND_WORDS

            raise InputError(f"--init-from {cfg.init_from}: {KIND_WORDS.get(held, held)}; a "
                             "primitive run starts only from a primitive run (`train --policy "
                             "primitive`)")
    if not cfg.encoder:
        raise InputError("--policy primitive needs --encoder FILE, the contact-pretrained CORN "
                         "encoder it reads (`corn-drake pretrain --model corn` writes "
                         "OUT/encoder.pt; the shipped one is models/weights/push_corn/encoder.pt)")
    from corn_drake.rl.device import training_device

    training_device(cfg.device, "--device")
    return cfg


def _as_recorded_encoder(out, recorded: str, requested: str) -> str:
    """The recorded encoder name when `requested` names a file with the same bytes as the run's
    own copy: the run copied the file it was started from to OUT/encoder.pt, so the very command
    that started it gives another spelling of the same encoder, and resuming with it must not be
    refused (paths compared by what they hold, not how they are spelled). Else `requested`, so
    the resume check names the difference."""
    import filecmp
    from pathlib import Path

    from corn_drake.rl.checkpoints import run_encoder_path

    if requested == recorded:
        return requested
    own, given = Path(run_encoder_path(out, recorded)), Path(requested)
    if own.is_file() and given.is_file() and filecmp.cmp(own, given, shallow=False):
        return recorded
    return requested


def run(args) -> int:
    from corn_drake.config.primitive import PrimitiveTrainConfig
    from corn_drake.nn.threads import torch_threads
    from corn_drake.rl.checkpoints import keep_encoder_copy, run_encoder_path
    from corn_drake.rl.pretrained_encoders import load_encoder
    from corn_drake.rl.training.primitive_trainer import PrimitiveTrainer
    from corn_drake.run_folders.resumable import ResumableRun

    def check_new():
        checked_config(requested_config(args, None))

    with ResumableRun.open(args.out, PrimitiveTrainConfig, resume_required=args.resume,
                           check_new=check_new) as run_folder:
        cfg = checked_config(requested_config(args, run_folder.recorded))
        if not run_folder.is_new:
            cfg.encoder = _as_recorded_encoder(run_folder.out, run_folder.recorded.encoder,
                                               cfg.encoder)
        run_folder.refuse_changes(cfg, may_grow=RESUME_MAY_GROW, may_change=RESUME_MAY_CHANGE,
                                  name=lambda field: f"--set {field}")
        encoder_file = run_encoder_path(run_folder.out, cfg.encoder)
        encoder = load_encoder("corn", encoder_file, cfg.allow_weak_encoder)
        trainer = PrimitiveTrainer(cfg, run_folder.out, encoder)  # reads, writes nothing
        if run_folder.is_new:  # the run keeps its own copy of the frozen encoder
            cfg.encoder = keep_encoder_copy(run_folder.out, encoder_file)
        run_folder.write_config(cfg, f"task {cfg.env.task.name}, policy primitive, "
                                     f"{cfg.total_steps} primitives")
        with torch_threads(args.torch_threads):
            metrics = trainer.train(progress=not args.no_progress)
    print(f"trained {metrics['global_step']} primitives; run folder {run_folder.out}")
    return 0
