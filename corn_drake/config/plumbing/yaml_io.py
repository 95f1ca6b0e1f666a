"""YAML plumbing shared by every config: typed configs as flat fields, Drake's variant tags kept
through plain YAML, and pickling of Drake's config structs (Ray ships configs to its workers).
"""

import copyreg
import dataclasses as dc
import typing
from typing import Any


def _from_yaml(schema, text: str):
    from pydrake.common.yaml import yaml_load_typed

    return yaml_load_typed(schema=schema, data=text)


def _reduce_as_yaml(value):
    from pydrake.common.yaml import yaml_dump_typed

    return _from_yaml, (type(value), yaml_dump_typed(value))


def pickle_as_yaml(schema) -> None:
    """Lets instances of one of Drake's config structs pickle, as their YAML (the text a run's
    config.yaml holds for them): Drake's structs do not pickle, and Ray ships configs to its
    workers (rl/workers/ray_workers.py)."""
    copyreg.pickle(schema, _reduce_as_yaml)


def config_fields(cfg) -> dict[str, Any]:
    """A typed config as {'a.b.c': value} of plain YAML values, through the same dump the run's
    config.yaml is written with (so Drake's config structs flatten too, and floats compare as
    the file holds them)."""
    from pydrake.common.yaml import yaml_dump_typed

    def flat(value, prefix):
        if not isinstance(value, dict):
            return {prefix: value}
        out = {}
        for key, item in value.items():
            out.update(flat(item, f"{prefix}.{key}" if prefix else str(key)))
        return out

    return flat(read_tagged_yaml(yaml_dump_typed(cfg)), "")


class TaggedMapping(dict):
    """A YAML mapping that carried a type tag (Drake's variants: `focal: !FovDegrees {y: 50}`,
    `goal: !PlanarGoal {...}`); flattened by config_fields as a `!` entry beside the fields."""

    def __init__(self, tag: str, items):
        super().__init__(items)
        self["!"] = tag


def _tagged_loader():
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    def construct(loader, tag, node):
        if isinstance(node, yaml.MappingNode):
            return TaggedMapping(tag, loader.construct_mapping(node, deep=True))
        return TaggedMapping(tag, {})  # `!Tag` alone, or `!Tag ''`: a variant with defaults

    Loader.add_multi_constructor("!", construct)
    return Loader


def _tagged_dumper():
    import yaml

    class Dumper(yaml.SafeDumper):
        pass

    def represent(dumper, data):
        fields = {k: v for k, v in data.items() if k != "!"}
        return dumper.represent_mapping("!" + data["!"], fields)

    Dumper.add_representer(TaggedMapping, represent)
    return Dumper


def read_tagged_yaml(text: str):
    """YAML text as plain data, keeping Drake's variant tags (TaggedMapping) where yaml.safe_load
    would refuse them."""
    import yaml

    return yaml.load(text, Loader=_tagged_loader())  # noqa: S506 (a SafeLoader subclass)


def dump_tagged_yaml(data) -> str:
    """The inverse of read_tagged_yaml: tags written back in front of their mappings."""
    import yaml

    return yaml.dump(data, Dumper=_tagged_dumper(), sort_keys=False)


def field_types(schema) -> dict[str, Any] | None:
    """{field name: type} of a config schema, a dataclass or one of Drake's bound config structs
    (MultibodyPlantConfig lists its fields in __fields__); None for anything else."""
    if dc.is_dataclass(schema):
        return typing.get_type_hints(schema)
    fields = getattr(schema, "__fields__", None)
    if isinstance(fields, tuple) and all(hasattr(f, "name") for f in fields):
        return {f.name: f.type for f in fields}
    return None
