"""RUN/config.yaml, a run's one source of truth: written when a run starts, read back to resume,
evaluate, ship and plot it; and which command (train or distill) wrote it.
"""

from pathlib import Path

from corn_drake.config.plumbing.loader import load_config
from corn_drake.config.training import DistillConfig, TrainConfig
from corn_drake.config.plumbing.yaml_io import field_types, read_tagged_yaml
from corn_drake.errors import InputError, MissingInputError


RUN_CONFIG = "config.yaml"  # in a run folder


# --- the run folder ----------------------------------------------------------------------------
def run_config_path(run_dir: str | Path) -> Path:
    return Path(run_dir) / RUN_CONFIG


def load_run_config(run_dir: str | Path) -> TrainConfig:
    """RUN/config.yaml, the config a run was trained with (and is resumed and evaluated with)."""
    path = run_config_path(run_dir)
    if not path.is_file():
        raise MissingInputError(f"{path} not found: is {run_dir} a run folder written by "
                                "`corn-drake train`?")
    return load_config(TrainConfig, path)


def write_run_config(cfg: TrainConfig, run_dir: str | Path) -> Path:
    from pydrake.common.yaml import yaml_dump_typed

    from corn_drake.storage.atomic_files import write_text

    path = run_config_path(run_dir)
    write_text(path, yaml_dump_typed(cfg))
    return path


def run_kind(run: str, or_else: str = "") -> str:
    """"train", "primitive" (train --policy primitive) or "distill": which command wrote the
    run folder `run`, told by the top-level
    keys of its config.yaml; a missing config or one of neither kind is an error naming --run
    (and `or_else`, what else the command would have taken)."""
    import yaml

    path = run_config_path(run)
    if not path.is_file():
        raise MissingInputError(f"--run {run}: {path} not found: expected a run folder written "
                                "by `corn-drake train` or `corn-drake distill`"
                                + (f", or {or_else}" if or_else else ""))
    try:
        data = read_tagged_yaml(path.read_text())
    except (UnicodeDecodeError, yaml.YAMLError) as e:  # neither kind of run
        raise InputError(f"--run {run}: {path} is not a YAML run config "
                         f"({' '.join(str(e).split())[:200]})") from None
    keys = set(data) if isinstance(data, dict) else set()
    if "primitive" in keys:  # PrimitiveTrainConfig's own section (train --policy primitive)
        return "primitive"
    # The top-level fields only one of the two configs has (both have env, seed, ...).
    train_fields, distill_fields = set(field_types(TrainConfig)), set(field_types(DistillConfig))
    train_only, distill_only = train_fields - distill_fields, distill_fields - train_fields
    if keys & distill_only and not keys & train_only:
        return "distill"
    if keys & train_only and not keys & distill_only:
        return "train"
    raise InputError(f"--run {run}: {path} is neither a `corn-drake train` (teacher) nor a "
                     "`corn-drake distill` (student) run config")
