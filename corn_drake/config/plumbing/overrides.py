"""Overrides of a typed config, the last layer: `--set KEY=VALUE` and a command's shortcut flags,
each loaded on top of the config by the one loader, and what they changed (Change) so commands
can print it and decide whether a resumed run may take it.
"""

import dataclasses as dc
import difflib
import json
import types
import typing
from typing import Any, Iterable, Mapping, TypeVar

from corn_drake.config.plumbing.loader import load_config
from corn_drake.config.retired import retired_message, retired_reason
from corn_drake.config.training import TrainConfig
from corn_drake.config.plumbing.yaml_io import (TaggedMapping, config_fields, dump_tagged_yaml,
                                                field_types, read_tagged_yaml)
from corn_drake.errors import InputError


# A run config's `env` sections may be named without `env.` (`--set task.episode_steps=50`):
# a key whose first part is not a field of the config itself but a section of its env (for
# TrainConfig: scene, randomization, controller, task; not seed, which TrainConfig has too).
ENV = "env"
T = TypeVar("T")


@dc.dataclass(frozen=True)
class Change:
    """One field an override changed; str() is how commands print it."""
    key: str  # dotted TrainConfig field, e.g. "env.task.episode_steps"
    old: Any
    new: Any

    def __str__(self) -> str:
        return f"{self.key} {json.dumps(self.old)} -> {json.dumps(self.new)}"


# --- layer 3: overrides -------------------------------------------------------------------------
def resolve_key(key: str, label: str, root: Any = TrainConfig) -> tuple[str, Any]:
    """(the field of config schema `root` that `key` names, with `env.` added before an env
    section; the field's type, or None where the schema cannot say, as inside a tagged union).
    An unknown key is an InputError naming it and the keys its section has."""
    parts = key.split(".")
    top = field_types(root) or {}
    added = 0  # the sections added before the user's spelling (env.)
    if parts[0] not in top and ENV in top and parts[0] in (field_types(top[ENV]) or {}):
        parts, added = [ENV, *parts], 1
    schema: Any = root
    for i, part in enumerate(parts):
        if typing.get_origin(schema) in (typing.Union, types.UnionType):
            return ".".join(parts), None  # which member holds the rest, the loader decides
        fields = field_types(schema)
        parent = ".".join(parts[:i]) or "the run config"
        if fields is None:
            raise InputError(f"{label}: unknown key {key!r}: {parent} is a value, not a section")
        if part not in fields and retired_reason(schema, part) is not None:
            raise InputError(retired_message(label, ".".join(parts[:i + 1]),
                                             retired_reason(schema, part)))
        if part not in fields:
            close = difflib.get_close_matches(part, list(fields), n=1, cutoff=0.6)
            hint = (f"did you mean {'.'.join([*parts[added:i], close[0]])!r}? " if close
                    else "")
            raise InputError(f"{label}: unknown key {'.'.join(parts[:i + 1])!r}; {hint}{parent} "
                             f"has {', '.join(fields)}")
        schema = fields[part]
    return ".".join(parts), schema


def set_fields(cfg: T, values: Mapping[str, Any], label: str) -> T:
    """`cfg` (any typed config) with typed `values` ({dotted field: value}) loaded on top as one
    layer."""
    data: dict = {}
    for key, value in values.items():
        *sections, leaf = resolve_key(key, label, type(cfg))[0].split(".")
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
    return load_config(type(cfg), text=dump_tagged_yaml(data), name=label, defaults=cfg)


def on_library(cfg: TrainConfig, library: str, label: str = "--objects") -> TrainConfig:
    """`cfg` training on every train object of `library`, a new one each episode (train
    --objects); rl/envs/vec_env.library_train_ids checks that the library can be cycled."""
    return set_fields(cfg, {"env.scene.object.kind": "library",
                            "env.scene.object.library": library,
                            "env.scene.object.library_objects": "train",
                            "env.scene.object.object_id": ""}, label)


def apply_sets(cfg: T, items: Iterable[str], only: str | tuple[str, ...] | None = None,
               option: str = "--set") -> T:
    """`cfg` with each `KEY=VALUE` of `items` loaded on top in turn, VALUE parsed as YAML (text
    as it is for a string field, so `--set encoder=123` is the file "123"). With `only`, a key
    outside that section or those sections (e.g. "env", or ("env", "primitive")) is refused."""
    import yaml

    sections = (only,) if isinstance(only, str) else only
    for item in items:
        label = f"{option} {item}"
        key, sep, text = item.partition("=")
        if not sep or not key:
            raise InputError(f"{label}: expected KEY=VALUE, e.g. ppo.lr=1e-4 or "
                             "task.episode_steps=50")
        key, kind = resolve_key(key.strip(), label, type(cfg))
        if sections is not None and not any(key.startswith(f"{section}.")
                                            for section in sections):
            raise InputError(f"{label}: only {' and '.join(f'{s}.*' for s in sections)} "
                             "settings apply here")
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
