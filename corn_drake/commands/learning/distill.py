"""`corn-drake distill`: DAgger distillation of a trained teacher into the student (rl/training/dagger.py).

The teacher is a PPO run (`corn-drake train`; a primitive run, trained with TD3, is no teacher
here); the student (camera point cloud -> CORN encoder -> GRU -> action) learns from it with
DAgger. The student's env is the teacher run's, with the student layer (`--config`), the `--task`
overlay and `--set KEY=VALUE` on top.
"""

from __future__ import annotations

import copy
from pathlib import Path

from corn_drake.arguments.renamed import add_renamed
from corn_drake.arguments.run_flags import (RESUME_MAY_CHANGE, RUN_SHORTCUTS, add_run_arguments,
                                            flag_of_field)
from corn_drake.arguments.torch_threads import add_torch_threads_argument
from corn_drake.arguments.value_types import (finite_float, nonnegative_int, positive_float,
                                               positive_int)

NAME = "distill"
HELP = ("distil a PPO-trained teacher run into the camera-based student with DAgger (resumes "
        "from OUT/checkpoints/last.pt)")

# Flags that set one DistillConfig field: argparse dest -> field (the run settings' shared flags,
# then distill's own). They default to None: a new run takes the field's default, a resumed
# run its recorded value.
SHORTCUTS = {**RUN_SHORTCUTS, "window": "window", "beta_start": "beta_start",
             "beta_anneal_steps": "beta_anneal_steps", "student_action": "student_action",
             "lr": "lr", "checkpoint_every": "checkpoint_every", "log_every": "log_every"}
# On resume total_steps may grow; where the workers and tensors live, and how often the run
# checkpoints and logs, do not change what it learns.
RESUME_MAY_GROW = ("total_steps",)
RESUME_MAY_CHANGE = (*RESUME_MAY_CHANGE, "log_every")


def add_arguments(parser):
    from corn_drake.config.choices import SEGMENTATION_MODES
    from corn_drake.config.choices import STUDENT_ACTIONS

    add_run_arguments(parser, NAME, encoder_help="contact-pretrained CORN encoder for the "
                                                 "student (default: the teacher run's encoder)")
    parser.add_argument("--run", dest="teacher", default=None, metavar="RUN",
                        help="the teacher's run folder (written by `corn-drake train`, PPO, or "
                             "shipped in models/weights/), as `evaluate --run`; required for a "
                             "new run (default: a resumed run's recorded one)")
    add_renamed(parser, "--teacher", "--run", " (the teacher's run folder, as in `evaluate`)")
    parser.add_argument("--task", default=None,
                        help="task overlay read on top of the teacher run's env: a name in "
                             "diagrams/tasks/ or a YAML file (default: the teacher's task)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", dest="set",
                        help="override a config field, e.g. --set window=16 or --set "
                             "task.episode_steps=50 (repeatable; KEY a DistillConfig field, the "
                             "student diagram's sections segmentation/cameras/tracker/"
                             "observation, or the teacher env's scene/randomization/controller/"
                             "task, without env. or env.teacher.; default: none)")
    parser.add_argument("--config", default=None,
                        help="student diagram layer read on top of the teacher run's env "
                             "(default: diagrams/student_rollout.yaml)")
    parser.add_argument("--objects", default=None,
                        help="object library folder: train on all its train objects "
                             "(default: the teacher run's objects)")
    parser.add_argument("--perception", choices=SEGMENTATION_MODES, default=None,
                        help="segmentation during training (default: the config's, geometric)")
    parser.add_argument("--window", type=positive_int, default=None,
                        help="BPTT window in steps, one optimiser step each (default: 8)")
    parser.add_argument("--beta-start", type=finite_float, default=None,
                        help="probability of executing the teacher's action at step 0 (default 1)")
    parser.add_argument("--beta-anneal-steps", type=nonnegative_int, default=None,
                        help="env steps over which beta falls linearly to 0 (default: 10000)")
    parser.add_argument("--student-action", choices=STUDENT_ACTIONS, default=None,
                        help="the student's own action: its mean (default) or a sample")
    parser.add_argument("--lr", type=positive_float, default=None,
                        help="the student's Adam learning rate (default: 3e-4)")
    parser.add_argument("--checkpoint-every", type=positive_int, default=None,
                        help="windows between checkpoints (default: 50)")
    parser.add_argument("--log-every", type=positive_int, default=None,
                        help="windows per metrics row and TensorBoard point (default: 10)")
    add_torch_threads_argument(parser, "the student's and teacher's inference and the DAgger "
                                       "updates (not recorded in the run: it changes the speed, "
                                       "not the results)")


def load_teacher(run: str):
    """(TrainConfig, TeacherAgent) of the teacher run folder `run`; anything that makes it no
    teacher run is an InputError naming --run."""
    from corn_drake.errors import InputError, MissingInputError
    from corn_drake.rl.runs.kinds import require_kind

    if not Path(run).is_dir():
        raise MissingInputError(f"--run {run}: no such run folder (the teacher's)")
    try:
        # Through the registry of run kinds (rl/runs/kinds.py): another kind is named as such.
        kind = require_kind(run, "train", needs="`distill`")
        loaded = kind.load(run)
    except InputError as e:
        raise InputError(f"--run {run} is not a trained teacher run: {e}") from None
    return loaded.config, loaded.agent


def student_env_config(teacher_env, layer: str | None):
    """The student diagram for a teacher trained on `teacher_env`: its scene, task and
    randomisation as the base, the student layer (`--config`) read on top."""
    from corn_drake.config.student import StudentDiagramConfig
    from corn_drake.config.plumbing.diagram_files import load_student_config

    return load_student_config(layer, base=StudentDiagramConfig(teacher=copy.deepcopy(teacher_env)))


def with_task(teacher_env, task: str | None):
    """The teacher run's env with the `--task` overlay read on top (None: as it is)."""
    if task is None:
        return teacher_env
    from corn_drake.config.plumbing.diagram_files import task_file
    from corn_drake.config.plumbing.loader import load_config
    from corn_drake.config.teacher import TeacherDiagramConfig

    path = task_file(task)
    env = copy.deepcopy(teacher_env)
    env.task.name = path.stem  # the name unless the overlay sets its own on top
    return load_config(TeacherDiagramConfig, path, defaults=env)


# The teacher env's sections, which --set names without env.teacher. (as train's --set does).
TEACHER_ENV_SECTIONS = ("scene", "randomization", "controller", "task")


def apply_distill_sets(cfg, items):
    """`cfg` with `--set KEY=VALUE` items on top: a key in one of TEACHER_ENV_SECTIONS is the
    teacher env's (env.teacher.KEY), a student diagram section's is env.KEY."""
    from corn_drake.config.plumbing.overrides import apply_sets

    for item in items:
        key = item.partition("=")[0].strip()
        full = f"env.teacher.{item.strip()}" if key.split(".")[0] in TEACHER_ENV_SECTIONS else item
        try:
            cfg = apply_sets(cfg, [full])
        except Exception as e:  # the error names the user's spelling, not the full key
            from corn_drake.errors import InputError

            if not isinstance(e, InputError) or full == item:
                raise
            raise InputError(str(e).replace(f"--set {full}", f"--set {item}", 1)) from None
    return cfg


def requested_config(args, recorded, teacher_cfg):
    """The DistillConfig `args` ask for, on top of the `recorded` one of a resumed run (None: a
    new run)."""
    from corn_drake.config.training import DistillConfig
    from corn_drake.errors import InputError

    task = getattr(args, "task", None)
    if recorded is None:
        cfg = DistillConfig(teacher=args.teacher, encoder=teacher_cfg.encoder,
                            env=student_env_config(with_task(teacher_cfg.env, task), args.config))
    else:
        cfg = copy.deepcopy(recorded)
        if args.teacher is not None:
            cfg.teacher = args.teacher
        if args.config is not None or task is not None:  # objects, segmentation: the run's
            env = student_env_config(with_task(teacher_cfg.env, task), args.config)
            env.teacher.scene.object = cfg.env.teacher.scene.object
            env.segmentation.mode = cfg.env.segmentation.mode
            cfg.env = env
    for dest, field in SHORTCUTS.items():
        value = getattr(args, dest)
        if value is not None:
            setattr(cfg, field, value)
    if args.objects is not None:
        obj = cfg.env.teacher.scene.object
        obj.kind, obj.library, obj.library_objects, obj.object_id = (
            "library", args.objects, "train", "")
    if args.perception is not None:
        cfg.env.segmentation.mode = args.perception
    cfg = apply_distill_sets(cfg, getattr(args, "set", None) or [])
    if not cfg.encoder:
        raise InputError(f"--encoder: the teacher run {cfg.teacher} ({teacher_cfg.policy} policy) "
                         "records no pretrained encoder; give the student's CORN encoder")
    cfg.check()
    return cfg


def run(args) -> int:
    from corn_drake.config.training import DistillConfig
    from corn_drake.errors import InputError
    from corn_drake.nn.student_io import student_from_encoder
    from corn_drake.nn.threads import torch_threads
    from corn_drake.rl.training.dagger import DaggerTrainer
    from corn_drake.rl.pretrained_encoders import check_pretrained
    from corn_drake.run_folders.config_file import run_config_path
    from corn_drake.run_folders.inputs_record import record_inputs, refuse_changed_inputs
    from corn_drake.run_folders.resumable import ResumableRun

    if not run_config_path(args.out).is_file() and args.teacher is None:
        raise InputError("--run is required for a new run (the teacher's run folder, written "
                         "by `corn-drake train`)")
    def check_new():  # a new run's own argument errors, named before a folder it cannot take
        requested_config(args, None, load_teacher(args.teacher)[0])

    with ResumableRun.open(args.out, DistillConfig, resume_required=args.resume,
                           check_new=check_new) as run_folder:
        recorded = run_folder.recorded
        teacher_cfg, teacher = load_teacher(args.teacher or recorded.teacher)
        cfg = requested_config(args, recorded, teacher_cfg)
        if cfg.env.teacher.scene.object.cycles_library:
            from corn_drake.rl.envs.vec_env import library_train_ids

            library_train_ids(cfg.env.teacher.scene.object.library)  # a bad library fails here
        run_folder.refuse_changes(cfg, may_grow=RESUME_MAY_GROW, may_change=RESUME_MAY_CHANGE,
                                  name=argument_of_field)
        import torch

        torch.manual_seed(cfg.seed)  # the student's fresh layers: a run is its seed's
        student = student_from_encoder(cfg.encoder, cfg.frozen)
        check_pretrained(student.encoder, cfg.encoder, cfg.allow_weak_encoder)
        trainer = DaggerTrainer(cfg, run_folder.out, student, teacher)  # reads, writes nothing
        # The teacher's very weights: a resume after it trained further would mix two teachers.
        inputs = {"teacher_weights": teacher_weights_hash(cfg.teacher)}
        refuse_changed_inputs(run_folder.out, inputs, "a student run")
        run_folder.write_config(cfg, f"teacher {cfg.teacher} ({teacher_cfg.policy}), perception "
                                     f"{cfg.env.segmentation.mode}, {cfg.total_steps} steps",
                                kind="student run", at_step=trainer.global_step)
        record_inputs(run_folder.out, inputs)
        with torch_threads(args.torch_threads):
            metrics = trainer.train(progress=not args.no_progress)
    print(f"distilled {metrics['global_step']} steps; run folder {run_folder.out}")
    return 0


def teacher_weights_hash(run: str) -> str:
    """rl/runs/loaded.weights_hash of the teacher run's config and last.pt."""
    from corn_drake.rl.checkpoints import weights_hash

    return weights_hash(Path(run), Path(run) / "checkpoints" / "last.pt")


def argument_of_field(field: str) -> str:
    """The distill argument behind a DistillConfig field, for refusal messages."""
    flag = flag_of_field(field, SHORTCUTS)
    if flag is not None:
        return flag
    if field == "teacher":
        return "--run"
    if field.startswith("env.teacher.scene.object."):
        return "--objects"
    if field.startswith("env.teacher.task."):
        return f"--task or --set {field[len('env.teacher.'):]}"
    if field == "env.segmentation.mode":
        return "--perception"
    if field.startswith("env.teacher."):
        return f"--config or --set {field[len('env.teacher.'):]}"
    if field.startswith("env."):
        return f"--config or --set {field[4:]}"
    return f"--set {field}"
