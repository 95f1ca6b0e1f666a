"""Loading a trained run: its TrainConfig and a TeacherAgent with the saved weights."""

from __future__ import annotations

from pathlib import Path

from corn_drake.config import TrainConfig
from corn_drake.errors import MissingInputError
from corn_drake.io_utils import load_checkpoint
from corn_drake.rl.agent import TeacherAgent
from corn_drake.rl.encoders import load_encoder
from corn_drake.run_config import load_run_config


def run_encoder_path(run_dir: str | Path, encoder: str) -> str:
    """The encoder file a run's config names. `train` records --encoder as given (relative to
    where it ran); shipped weights (models/weights/, `corn-drake ship`) name theirs relative to
    their own folder, so a relative path that exists there is taken from there."""
    if encoder and not Path(encoder).is_absolute() and (Path(run_dir) / encoder).is_file():
        return str(Path(run_dir) / encoder)
    return encoder


def load_run(run_dir: str | Path) -> tuple[TrainConfig, TeacherAgent]:
    run_dir = Path(run_dir)
    cfg = load_run_config(run_dir)
    cfg.encoder = run_encoder_path(run_dir, cfg.encoder)  # what distill's student starts from too
    ckpt = run_dir / "checkpoints" / "last.pt"
    state = load_checkpoint(ckpt, required=("agent",))  # falls back to prev.pt if need be
    if state is None:
        raise MissingInputError(f"no checkpoint in {run_dir}: expected {ckpt}")
    encoder = load_encoder(cfg.policy, cfg.encoder, cfg.allow_weak_encoder)
    # Runs from before feature normalisation existed hold no feature_normalizer: their
    # checkpoint, not today's default, says how their network was built.
    normalize = any(k.startswith("feature_normalizer.") for k in state["agent"])
    agent = TeacherAgent(cfg.policy, encoder, separate_critic=cfg.ppo.separate_critic,
                         normalize_features=normalize)
    agent.load_saved_state(state["agent"], ckpt)
    agent.eval()
    return cfg, agent


def load_student_run(run_dir: str | Path):
    """(DistillConfig, StudentPolicy in eval mode) of a `corn-drake distill` run folder, from its
    config.yaml and checkpoints/last.pt (prev.pt if need be). The student's state_dict carries
    its encoder's input normalisation and token statistics, so no encoder file is read."""
    from corn_drake.config import load_config
    from corn_drake.config_distill import DistillConfig
    from corn_drake.errors import InputError
    from corn_drake.nn.student import StudentPolicy
    from corn_drake.run_config import run_config_path

    run_dir = Path(run_dir)
    path = run_config_path(run_dir)
    if not path.is_file():
        raise MissingInputError(f"{path} not found: is {run_dir} a run folder written by "
                                "`corn-drake distill`?")
    cfg = load_config(path, DistillConfig)
    ckpt = run_dir / "checkpoints" / "last.pt"
    state = load_checkpoint(ckpt, required=("kind", "student"))
    if state is None or state["kind"] != "student":
        raise MissingInputError(f"no student checkpoint in {run_dir}: expected {ckpt}")
    student = StudentPolicy()
    try:
        student.load_state_dict(state["student"])
    except RuntimeError as e:
        raise InputError(f"{ckpt}: the saved student does not fit this version "
                         f"({str(e).strip().splitlines()[-1].strip()})") from None
    return cfg, student.eval()
