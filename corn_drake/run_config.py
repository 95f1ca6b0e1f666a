"""A run's config, its one source of truth: built in layers, written into the run, read back.

Layers, each loaded by pydrake's yaml_load_typed on top of the one before (`defaults=`), so
every layer names only what differs and is type-checked by the same loader, in the spirit of
Drake's LoadScenario(defaults=...):

  1. the base diagram, diagrams/teacher_rollout.yaml (a TeacherDiagramConfig);
  2. a task overlay (`--task NAME` -> diagrams/tasks/NAME.yaml, or `--task PATH`);
  3. overrides: a command's shortcut flags (`train --steps`) and `--set KEY=VALUE`, KEY a
     TrainConfig field (`ppo.lr`, `env.task.episode_steps`, or `task.episode_steps`: the env's
     sections need no `env.` prefix).

`train` writes the resolved TrainConfig into RUN/config.yaml; `load_run_config` is the one
reader of it (resume, `evaluate`, `curves`, notebooks). Against an existing config, an
explicit argument is an override, and the functions here return what it changed (Change) so
the command can print it and decide whether it is allowed.
"""

import dataclasses as dc
import json
import types
import typing
from pathlib import Path
from typing import Any, Iterable, Mapping

from corn_drake import DIAGRAMS_DIR
from corn_drake.config import (TaggedMapping, TeacherDiagramConfig, TrainConfig, config_fields,
                               dump_tagged_yaml, field_types, load_config, load_config_string,
                               read_tagged_yaml)
from corn_drake.errors import InputError, MissingInputError

BASE_DIAGRAM = DIAGRAMS_DIR / "teacher_rollout.yaml"
TASKS_DIR = DIAGRAMS_DIR / "tasks"
RUN_CONFIG = "config.yaml"  # in a run folder
# TrainConfig.env's sections: `--set` may name them without `env.` (TrainConfig has no others
# of these names, so the short form is unambiguous). Not `seed`: TrainConfig has its own.
ENV_SECTIONS = ("scene", "randomization", "controller", "task")


@dc.dataclass(frozen=True)
class Change:
    """One field an override changed; str() is how commands print it."""
    key: str  # dotted TrainConfig field, e.g. "env.task.episode_steps"
    old: Any
    new: Any

    def __str__(self) -> str:
        return f"{self.key} {json.dumps(self.old)} -> {json.dumps(self.new)}"


# --- layers 1 and 2: base diagram and task overlay ----------------------------------------------
def available_tasks() -> list[str]:
    return sorted(p.stem for p in TASKS_DIR.glob("*.yaml"))


def task_file(task: str | Path) -> Path:
    """The overlay `--task` names: a task in diagrams/tasks/, or a YAML file's path."""
    path = Path(task)
    if path.suffix in (".yaml", ".yml") or len(path.parts) > 1:
        if not path.is_file():
            raise MissingInputError(f"--task {task}: no such file")
        return path
    named = TASKS_DIR / f"{task}.yaml"
    if not named.is_file():
        raise InputError(f"--task {task}: no such task; the tasks are "
                         f"{', '.join(available_tasks()) or '(none)'} (in {TASKS_DIR}), or give "
                         "a task YAML file's path")
    return named


def load_base_config() -> TeacherDiagramConfig:
    return load_config(BASE_DIAGRAM, TeacherDiagramConfig)


def load_env_config(task: str | Path | None = None) -> TeacherDiagramConfig:
    """The base diagram with `task`'s overlay on top (None: the base alone, the paper's task).
    The task's name is the overlay's task.name if it sets one, else the file's stem."""
    cfg = load_base_config()
    if task is None:
        return cfg
    path = task_file(task)
    cfg.task.name = path.stem  # the name unless the overlay sets its own on top
    return load_config(path, TeacherDiagramConfig, defaults=cfg)


def replace_task(cfg: TrainConfig, task: str | Path) -> TrainConfig:
    """`cfg` with its env rebuilt from the base and `task`'s overlay. The object(s) stay cfg's:
    they are chosen apart from the task (`train --objects`)."""
    env = load_env_config(task)
    env.scene.object = cfg.env.scene.object
    return dc.replace(cfg, env=env)


# --- layer 3: overrides -------------------------------------------------------------------------
def resolve_key(key: str, label: str) -> tuple[str, Any]:
    """(the TrainConfig field `key` names, with `env.` added before an env section; the field's
    type, or None where the schema cannot say, as inside a tagged union). An unknown key is an
    InputError naming it and the keys its section has."""
    parts = key.split(".")
    if parts[0] in ENV_SECTIONS:
        parts = ["env", *parts]
    schema: Any = TrainConfig
    for i, part in enumerate(parts):
        if typing.get_origin(schema) in (typing.Union, types.UnionType):
            return ".".join(parts), None  # which member holds the rest, the loader decides
        fields = field_types(schema)
        parent = ".".join(parts[:i]) or "the run config"
        if fields is None:
            raise InputError(f"{label}: unknown key {key!r}: {parent} is a value, not a section")
        if part not in fields:
            raise InputError(f"{label}: unknown key {'.'.join(parts[:i + 1])!r}; {parent} has "
                             f"{', '.join(fields)}")
        schema = fields[part]
    return ".".join(parts), schema


def set_fields(cfg: TrainConfig, values: Mapping[str, Any], label: str) -> TrainConfig:
    """`cfg` with typed `values` ({dotted field: value}) loaded on top as one layer."""
    data: dict = {}
    for key, value in values.items():
        *sections, leaf = resolve_key(key, label)[0].split(".")
        node, current = data, cfg
        for section in sections:
            union = typing.get_origin((field_types(type(current)) or {}).get(section)) in (
                typing.Union, types.UnionType)
            current = getattr(current, section, None)  # None: a key the loader will refuse
            # A section that is a tagged variant (task.goal) keeps the tag of the variant it
            # holds: an untagged mapping would load as the union's first variant.
            node = node.setdefault(section, TaggedMapping(type(current).__name__, {})
                                   if union else {})
        node[leaf] = value
    return load_config_string(dump_tagged_yaml(data), TrainConfig, label, defaults=cfg)


def on_library(cfg: TrainConfig, library: str, label: str = "--objects") -> TrainConfig:
    """`cfg` training on every train object of `library`, a new one each episode (train
    --objects); rl/vec_env.library_train_ids checks that the library can be cycled."""
    return set_fields(cfg, {"env.scene.object.kind": "library",
                            "env.scene.object.library": library,
                            "env.scene.object.library_objects": "train",
                            "env.scene.object.object_id": ""}, label)


def apply_sets(cfg: TrainConfig, items: Iterable[str], only: str | None = None,
               option: str = "--set") -> TrainConfig:
    """`cfg` with each `KEY=VALUE` of `items` loaded on top in turn, VALUE parsed as YAML (text
    as it is for a string field, so `--set encoder=123` is the file "123"). With `only`, a key
    outside that section (e.g. "env") is refused."""
    import yaml

    for item in items:
        label = f"{option} {item}"
        key, sep, text = item.partition("=")
        if not sep or not key:
            raise InputError(f"{label}: expected KEY=VALUE, e.g. ppo.lr=1e-4 or "
                             "task.episode_steps=50")
        key, kind = resolve_key(key.strip(), label)
        if only is not None and not key.startswith(f"{only}."):
            raise InputError(f"{label}: only {only}.* settings apply here")
        try:
            value = read_tagged_yaml(text)  # a variant's tag too: task.goal='!PlanarGoal {}'
        except yaml.YAMLError as e:
            raise InputError(f"{label}: the value is not valid YAML ({' '.join(str(e).split())})"
                             ) from None
        if kind is str and not isinstance(value, (str, list, dict)):
            value = text
        cfg = set_fields(cfg, {key: value}, label)
    return cfg


def config_changes(before, after) -> list[Change]:
    """Every field whose value differs between two configs of one schema, including fields only
    one side has (another variant of a tagged union, e.g. a task's goal: the one side's value
    is then None)."""
    old, new = config_fields(before), config_fields(after)
    keys = list(new) + [key for key in old if key not in new]
    return [Change(key, old.get(key), new.get(key)) for key in keys
            if old.get(key) != new.get(key)]


# --- the run folder ----------------------------------------------------------------------------
def run_config_path(run_dir: str | Path) -> Path:
    return Path(run_dir) / RUN_CONFIG


def load_run_config(run_dir: str | Path) -> TrainConfig:
    """RUN/config.yaml, the config a run was trained with (and is resumed and evaluated with)."""
    path = run_config_path(run_dir)
    if not path.is_file():
        raise MissingInputError(f"{path} not found: is {run_dir} a run folder written by "
                                "`corn-drake train`?")
    return load_config(path, TrainConfig)


def write_run_config(cfg: TrainConfig, run_dir: str | Path) -> Path:
    from pydrake.common.yaml import yaml_dump_typed

    from corn_drake.io_utils import write_text

    path = run_config_path(run_dir)
    write_text(path, yaml_dump_typed(cfg))
    return path
