"""The one loader of every typed config (teacher, student, train, distill, pretraining): a YAML
file or text read by pydrake's yaml_load_typed on top of `defaults`, in the spirit of Drake's
LoadScenario(filename, scenario_text, defaults). Unknown keys and wrong types are InputErrors
naming the file (and the field, where there is one); layering (base -> overlay -> --set) is
built from this in config/plumbing/diagram_files.py and config/plumbing/overrides.py.
"""

import typing
from pathlib import Path
from typing import TypeVar

from corn_drake.config.retired import refuse_retired
from corn_drake.config.plumbing.yaml_io import dump_tagged_yaml, field_types, read_tagged_yaml
from corn_drake.errors import InputError, MissingInputError


T = TypeVar("T")


def load_config(schema: type[T], filename: str | Path | None = None, *, text: str | None = None,
                name: str | None = None, defaults: T | None = None) -> T:
    """One layer of a typed config: the YAML file `filename` (or the YAML `text`, which `name`
    says where it came from) loaded into `schema` on top of `defaults` (the layer below; not
    modified), or on top of the schema's defaults. A missing file, bad YAML, an unknown key or
    a value of the wrong type raises an InputError naming the file (and the field, where
    there is one). Exactly one of filename and text."""
    if (filename is None) == (text is None):
        raise TypeError("load_config takes exactly one of filename and text")
    if text is not None:
        return _load_typed(schema, name or "<string>", defaults, data=text)
    path = Path(filename)
    if not path.is_file():
        raise MissingInputError(f"config file not found: {path}")
    return _load_typed(schema, name or str(path), defaults, filename=str(path))


# What drake's yaml_load_typed raises for a value the schema cannot take: RuntimeError names
# the key; a scalar it cannot convert leaks a bare ValueError/TypeError; a scalar where a
# mapping belongs fails one of its asserts.
_LOAD_ERRORS = (RuntimeError, ValueError, TypeError, AssertionError)


def _load_typed(schema: type[T], name: str, defaults: T | None = None, **source) -> T:
    from pydrake.common.yaml import yaml_load_typed
    import yaml

    try:
        if defaults is None:
            return yaml_load_typed(schema=schema, **source)
        return yaml_load_typed(schema=schema, defaults=defaults, **source)
    except UnicodeDecodeError:
        raise InputError(f"invalid config {name}: not a UTF-8 text file") from None
    except yaml.YAMLError as e:
        raise InputError(f"invalid config {name}: not valid YAML ({_one_line(e)})") from e
    except RuntimeError as e:
        # drake's "unknown key": a retired setting says so instead (config/retired.py).
        text = source["data"] if "data" in source else Path(source["filename"]).read_text()
        refuse_retired(schema, read_tagged_yaml(text), f"invalid config {name}")
        raise InputError(f"invalid config {name}: {_one_line(e)}") from e
    except _LOAD_ERRORS as e:
        text = source["data"] if "data" in source else Path(source["filename"]).read_text()
        found = _failing_field(schema, read_tagged_yaml(text))
        # drake's asserts carry only the offending value as their message.
        detail = "wrong type" if isinstance(e, AssertionError) else _one_line(e)
        if found is None:
            raise InputError(f"invalid config {name}: {detail}") from e
        field, value = found
        raise InputError(f"invalid config {name}: field {field} = {value!r}: {detail}") from e


def _failing_field(schema: type, data, path: str = "") -> tuple[str, object] | None:
    """(dotted name, value) of the first field of `data` (found at `path`) that `schema` cannot
    load, found by loading one field at a time with drake's loader, so the verdict is its own."""
    from pydrake.common.yaml import yaml_load_typed

    if not isinstance(data, dict):
        return (path, data) if path else None
    types = field_types(schema) or {}
    for key, value in data.items():
        if key not in types:
            continue  # an unknown key fails with drake's own RuntimeError naming it
        try:
            yaml_load_typed(schema=schema, data=dump_tagged_yaml({key: value}))
        except _LOAD_ERRORS:
            name = f"{path}.{key}" if path else str(key)
            field_type = types[key]
            if typing.get_origin(field_type) is typing.Union:  # a tagged variant (task.goal)
                variants = {v.__name__: v for v in typing.get_args(field_type)}
                tag = value.get("!") if isinstance(value, dict) else None
                field_type = variants.get(tag, typing.get_args(field_type)[0])
            if field_types(field_type) is not None:
                return _failing_field(field_type, value, name) or (name, value)
            return name, value
    return None


def _one_line(error: Exception) -> str:
    return " ".join(str(error).split())
