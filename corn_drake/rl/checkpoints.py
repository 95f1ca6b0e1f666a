"""A run folder's files: where its encoder, weights and snapshots are, the env hash its checkpoints
carry, what --init-from may start from, a DAgger student's loading, and the hash of the weights
a report measured. The dense teacher's loading is rl/ppo/teacher_runs.py (it needs the agent)."""

from __future__ import annotations

from pathlib import Path

from corn_drake.config.training import TrainConfig
from corn_drake.errors import InputError, MissingInputError, load_error_detail
from corn_drake.storage.checkpoint_files import load_checkpoint, load_checkpoint_and_file
from corn_drake.run_folders.config_file import load_run_config


def run_encoder_path(run_dir: str | Path, encoder: str) -> str:
    """The encoder file a run's config names. `train` records --encoder as given (relative to
    where it ran); shipped weights (models/weights/, `corn-drake ship`) name theirs relative to
    their own folder, so a relative path that exists there is taken from there."""
    found = run_relative_path(run_dir, encoder) if encoder else None
    return str(found) if found is not None and found != Path(encoder) else encoder  # as given


# What a primitive run folder calls its own copy of the frozen encoder (config `encoder`).
OWN_ENCODER = "encoder.pt"


def keep_encoder_copy(run_dir: str | Path, encoder_file: str | Path) -> str:
    """Copies `encoder_file` into the run folder (atomically) so the run evaluates and ships
    without the file it started from; returns the name its config records."""
    import shutil

    from corn_drake.storage.atomic_files import atomic_path

    with atomic_path(Path(run_dir) / OWN_ENCODER) as tmp:
        shutil.copyfile(encoder_file, tmp)
    return OWN_ENCODER


def run_relative_path(run_dir: str | Path, name: str) -> Path:
    """A file or folder a run's config names (its encoder, PrimitiveTrainConfig.agent_weights):
    relative to the run folder where it exists there, else as given."""
    if not Path(name).is_absolute() and (Path(run_dir) / name).exists():
        return Path(run_dir) / name
    return Path(name)


def agent_weights_folder(run_dir: str | Path, agent_weights: str) -> Path:
    """The folder whose checkpoints/ hold a primitive run's actor and critic: the run's own, or
    the one its config's agent_weights names (a shipped outcome-model folder's sibling)."""
    return run_relative_path(run_dir, agent_weights) if agent_weights else Path(run_dir)


def snapshot_path(run_dir: str | Path, step: int) -> Path:
    """Where a training run keeps its checkpoint of env step `step` (TrainConfig.snapshot_every)."""
    return Path(run_dir) / "checkpoints" / f"step_{step:09d}.pt"


def run_snapshots(run_dir: str | Path) -> list[str]:
    """The kept checkpoints' file names of a run, oldest first."""
    return sorted(p.name for p in (Path(run_dir) / "checkpoints").glob("step_*.pt"))


def load_student_run(run_dir: str | Path):
    """(DistillConfig, StudentPolicy in eval mode) of a `corn-drake distill` run folder, from its
    config.yaml and checkpoints/last.pt (prev.pt if need be). The student's state_dict carries
    its encoder's input normalisation and token statistics, so no encoder file is read."""
    cfg, student, _ = load_student_run_with_step(run_dir)
    return cfg, student


def load_student_run_with_step(run_dir: str | Path):
    """load_student_run's (config, student) and the env steps its checkpoint was distilled for;
    the student's `checkpoint_file` is the file the weights came from (prev.pt after a
    fallback), as a teacher's is, so a report can say which weights it measured."""
    from corn_drake.config.plumbing.loader import load_config
    from corn_drake.config.training import DistillConfig
    from corn_drake.errors import InputError
    from corn_drake.nn.student import StudentPolicy
    from corn_drake.run_folders.config_file import run_config_path

    run_dir = Path(run_dir)
    path = run_config_path(run_dir)
    if not path.is_file():
        raise MissingInputError(f"{path} not found: is {run_dir} a run folder written by "
                                "`corn-drake distill`?")
    cfg = load_config(DistillConfig, path)
    ckpt = run_dir / "checkpoints" / "last.pt"
    loaded = load_checkpoint_and_file(ckpt, required=("kind", "student"))
    if loaded is None or loaded[0]["kind"] != "student":
        raise MissingInputError(f"no student checkpoint in {run_dir}: expected {ckpt}")
    state, used = loaded
    check_env_hash(state, cfg, run_dir, used)
    student = StudentPolicy()
    try:
        student.load_state_dict(state["student"])
    except RuntimeError as e:
        raise InputError(f"{ckpt}: the saved student does not fit this version "
                         f"({load_error_detail(e)})") from None
    student.checkpoint_file = used.name
    return cfg, student.eval(), int(state.get("global_step", 0))


def _refuse_init_of_another_kind(source: Path) -> None:
    """A run folder of another kind than a dense teacher's, named in one line with what it is
    (its config would otherwise be reported field by field as unknown)."""
    from corn_drake.errors import InputError
    from corn_drake.run_folders.config_file import run_kind

    try:
        kind = run_kind(str(source))
    except (MissingInputError, InputError):
        return  # no run config of any kind: load_run_config names what is wrong
    if kind == "primitive":
        raise InputError(f"--init-from {source}: a contact-primitive run; a dense teacher "
                         "starts only from a dense teacher run (`train --policy primitive "
                         "--init-from` takes a primitive run)")
    if kind == "distill":
        raise InputError(f"--init-from {source}: a DAgger student run; a dense teacher starts "
                         "only from a dense teacher run (`corn-drake train`)")


def check_init_source(cfg: TrainConfig, take_policy: bool = False) -> TrainConfig:
    """`cfg` with the encoder (when it names none) and, with take_policy, the policy of its
    init_from run filled in, after checking that the source's agent fits: same policy and critic
    layout, the same encoder file. InputError naming --init-from
    otherwise. (The Trainer reads the source's checkpoint, before `train` writes anything.)"""
    import dataclasses

    from corn_drake.errors import InputError

    source = Path(cfg.init_from)
    _refuse_init_of_another_kind(source)
    try:
        src = load_run_config(source)
    except (MissingInputError, InputError) as e:
        raise InputError(f"--init-from {source}: not a training run ({e})") from None
    if take_policy:
        cfg = dataclasses.replace(cfg, policy=src.policy)
    for field, ours, theirs in (("policy", cfg.policy, src.policy),
                                ("ppo.separate_critic", cfg.ppo.separate_critic, src.ppo.separate_critic)):
        if ours != theirs:
            raise InputError(f"--init-from {source}: its {field} is {theirs!r}, this run's "
                             f"{ours!r}; the agent's weights fit only the same network")
    encoder = run_encoder_path(source, src.encoder)
    if not cfg.encoder:
        cfg = dataclasses.replace(cfg, encoder=encoder)
    elif Path(cfg.encoder).resolve() != Path(encoder).resolve():
        raise InputError(f"--init-from {source}: it was trained on encoder {encoder}, this run "
                         f"names {cfg.encoder}; leave --encoder off to take the source's")
    return cfg


def init_agent_state(source: str | Path) -> dict:
    """The trained agent's state_dict of run `source` (its last checkpoint)."""
    ckpt = Path(source) / "checkpoints" / "last.pt"
    state = load_checkpoint(ckpt, required=("agent",))
    if state is None:
        raise MissingInputError(f"--init-from {source}: no checkpoint (expected {ckpt})")
    return state["agent"]


# --- the config a checkpoint was trained with ---------------------------------------------------
def env_hash(cfg) -> str:
    """sha256 of what a run's episodes are (its `env`, and a primitive run's `primitive`
    settings), the library's path left out (a library may move): saved in every checkpoint, so
    a config.yaml edited afterwards (task push -> full6d) cannot make a report say it measured
    what the weights were not trained on."""
    import dataclasses
    import hashlib
    import json

    parts = {"env": dataclasses.asdict(cfg.env)}
    if getattr(cfg, "primitive", None) is not None:
        parts["primitive"] = dataclasses.asdict(cfg.primitive)
    _drop_library_paths(parts)
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()


def _drop_library_paths(value) -> None:
    if isinstance(value, dict):
        value.pop("library", None)
        for item in value.values():
            _drop_library_paths(item)


def check_env_hash(state: dict, cfg, run_dir, checkpoint) -> None:
    """An InputError naming the run's config.yaml when `state` (a checkpoint) was trained with
    another env than `cfg` says; checkpoints from before the hash was saved are not checked."""
    from corn_drake.errors import InputError
    from corn_drake.run_folders.config_file import run_config_path

    saved = state.get("env_sha256")
    if saved is not None and saved != env_hash(cfg):
        raise InputError(f"{run_config_path(Path(run_dir))}: its env (task, scene, controller, "
                         f"primitive settings) is not the one {checkpoint} was trained with: "
                         "the config was edited after training; restore it (evaluate --task / "
                         "--set change what an evaluation plays without editing the run)")


# --- what a report measured --------------------------------------------------------------------
# The files beside a primitive run's checkpoint that choose for it (an outcome model, a learned
# 6D chooser): part of its weights_hash.
CHOOSER_FILES = ("outcome_model.pt", "chooser_value.pt")


def weights_hash(run_dir: Path, checkpoint: Path) -> str:
    """sha256 over run folder `run_dir`'s config.yaml, its weights' `checkpoint` file and the
    chooser files beside them (CHOOSER_FILES)."""
    import hashlib

    from corn_drake.run_folders.config_file import run_config_path

    digest = hashlib.sha256()
    files = [run_config_path(run_dir), checkpoint,
             *(run_dir / name for name in CHOOSER_FILES if (run_dir / name).is_file())]
    for path in files:
        digest.update(Path(path).name.encode() + b"\0" + Path(path).read_bytes())
    return digest.hexdigest()
