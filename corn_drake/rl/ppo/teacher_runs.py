"""Loading a dense teacher run: its TrainConfig and a TeacherAgent with the saved weights (the
run folder's paths and checks are rl/checkpoints.py's)."""

from __future__ import annotations

from pathlib import Path

from corn_drake.config.training import TrainConfig
from corn_drake.errors import InputError, MissingInputError
from corn_drake.rl.checkpoints import check_env_hash, run_encoder_path, run_snapshots
from corn_drake.rl.ppo.agent import TeacherAgent
from corn_drake.rl.pretrained_encoders import load_encoder
from corn_drake.run_folders.config_file import load_run_config
from corn_drake.storage.checkpoint_files import load_checkpoint_and_file


def load_run(run_dir: str | Path, checkpoint: str = "") -> tuple[TrainConfig, TeacherAgent]:
    """A run's config and agent, from checkpoints/last.pt or, given `checkpoint`, from that file
    name in its checkpoints folder (a kept snapshot, e.g. step_000204800.pt)."""
    cfg, agent, _ = load_run_with_step(run_dir, checkpoint)
    return cfg, agent


def load_run_with_step(run_dir: str | Path, checkpoint: str = "") -> tuple[TrainConfig, TeacherAgent, int]:
    """load_run's (config, agent) and the env steps the loaded checkpoint was trained for."""
    run_dir = Path(run_dir)
    cfg = load_run_config(run_dir)
    cfg.encoder = run_encoder_path(run_dir, cfg.encoder)  # what distill's student starts from too
    if checkpoint:
        ckpt = run_dir / "checkpoints" / checkpoint
        if Path(checkpoint).name != checkpoint or not ckpt.is_file():
            kept = ", ".join(run_snapshots(run_dir)) or "none"
            raise MissingInputError(f"--checkpoint {checkpoint!r}: no such file in "
                                    f"{run_dir / 'checkpoints'} (kept snapshots: {kept})")
        loaded = load_checkpoint_and_file(ckpt, required=("agent",), fallback=False)
    else:
        ckpt = run_dir / "checkpoints" / "last.pt"
        # Falls back to prev.pt if need be.
        loaded = load_checkpoint_and_file(ckpt, required=("agent",))
    if loaded is None:
        raise MissingInputError(f"no checkpoint in {run_dir}: expected {ckpt}")
    state, used = loaded
    check_env_hash(state, cfg, run_dir, used)
    encoder = load_encoder(cfg.policy, cfg.encoder, cfg.allow_weak_encoder)
    if any(k.startswith("feature_normalizer.") for k in state["agent"]):
        raise InputError(f"{used}: trained with normalize_features, which was retired "
                         "(config/retired.py); the run cannot be loaded")
    agent = TeacherAgent(cfg.policy, encoder, separate_critic=cfg.ppo.separate_critic)
    agent.load_saved_state(state["agent"], ckpt)
    agent.eval()
    # The file the weights came from: prev.pt when last.pt was unusable (load_checkpoint).
    agent.checkpoint_file = used.name
    return cfg, agent, int(state.get("global_step", 0))
