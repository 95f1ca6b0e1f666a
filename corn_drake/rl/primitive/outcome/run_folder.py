"""A primitive run folder that chooses by an outcome model (config `chooser: outcome_model`):
what `corn-drake fit-outcome --out-run` writes, and `evaluate`, `ship`
and `gallery` read like any primitive run (rl/primitive/agent.load_primitive_run).

It holds the proposing run's config (the task and settings it is evaluated under), its agent
weights (the actor proposes one motion per location; the critic is unused) and the model.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from corn_drake.rl.primitive.outcome.model_file import save_outcome_model
from corn_drake.rl.primitive.outcome.model import MODEL_FILE


def outcome_run_config(run: Path, task: str | None, sets: list[str]):
    """The proposing run's config with chooser outcome_model, its encoder named as this folder
    reads it, `task`'s overlay and `sets` applied as `corn-drake evaluate` applies them."""
    from corn_drake.config.plumbing.diagram_files import primitive_run_on
    from corn_drake.rl.checkpoints import run_encoder_path
    from corn_drake.rl.primitive.agent import load_primitive_run

    base, _, _ = load_primitive_run(run)
    cfg = primitive_run_on(base, task, sets)
    cfg.check()
    # The new folder holds its own copy of the actor and critic (write_outcome_run).
    return dataclasses.replace(cfg, chooser="outcome_model", agent_weights="",
                               encoder=run_encoder_path(run, base.encoder))


def write_outcome_run(run: Path, cfg, model, tokens: bool, facts: dict, out: Path,
                      more: dict | None = None) -> None:
    """`out`: a primitive run folder that chooses by `model`: `cfg`, the proposing run's agent
    weights (checkpoints/last.pt) and the model (outcome_model.pt, as
    rl/primitive/outcome/model_file.save_outcome_model writes it); `more`: {file name: a
    function writing it to the path given} (a learned chooser's network). Built beside `out`
    and renamed into place, so `out` is whole or absent."""
    import shutil
    import tempfile

    from corn_drake.config.plumbing.loader import load_config
    from corn_drake.config.primitive import PrimitiveTrainConfig
    from corn_drake.errors import MissingInputError
    from corn_drake.rl.checkpoints import agent_weights_folder
    from corn_drake.run_folders.config_file import run_config_path, write_run_config
    from corn_drake.storage.checkpoint_files import load_checkpoint_and_file

    # The proposing run's actor and critic: its own, or (a shipped outcome folder) those of the
    # folder its agent_weights names.
    named = load_config(PrimitiveTrainConfig, run_config_path(run)).agent_weights
    checkpoint = agent_weights_folder(run, named) / "checkpoints" / "last.pt"
    loaded = load_checkpoint_and_file(checkpoint, ("agent",))
    if loaded is None:
        raise MissingInputError(f"{run}: no actor and critic to propose motions ({checkpoint})")
    used = loaded[1]
    out.parent.mkdir(parents=True, exist_ok=True)
    building = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    building.chmod(0o755)  # mkdtemp makes it private; a run folder is not
    try:
        (building / "checkpoints").mkdir()
        shutil.copyfile(used, building / "checkpoints" / "last.pt")
        save_outcome_model(building / MODEL_FILE, model, tokens, **facts)
        for name, write in (more or {}).items():
            write(building / name)
        write_run_config(cfg, building)
        building.rename(out)
    except BaseException:
        shutil.rmtree(building, ignore_errors=True)
        raise
