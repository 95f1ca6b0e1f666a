"""Loading a trained run: its TrainConfig and a TeacherAgent with the saved weights."""

from __future__ import annotations

from pathlib import Path

from corn_drake.config import TrainConfig
from corn_drake.errors import MissingInputError
from corn_drake.io_utils import load_checkpoint
from corn_drake.rl.agent import TeacherAgent
from corn_drake.rl.encoders import load_encoder
from corn_drake.run_config import load_run_config


def load_run(run_dir: str | Path) -> tuple[TrainConfig, TeacherAgent]:
    run_dir = Path(run_dir)
    cfg = load_run_config(run_dir)
    ckpt = run_dir / "checkpoints" / "last.pt"
    state = load_checkpoint(ckpt, required=("agent",))  # falls back to prev.pt if need be
    if state is None:
        raise MissingInputError(f"no checkpoint in {run_dir}: expected {ckpt}")
    agent = TeacherAgent(cfg.policy, load_encoder(cfg.policy, cfg.encoder, cfg.allow_weak_encoder))
    agent.load_state_dict(state["agent"])
    agent.eval()
    return cfg, agent
