"""Settings that were removed after they measured no gain (issue 52), so a user's old run folder
or `--set` naming one is told so in one line instead of drake's "unknown key".

RETIRED maps (config class name, field name) to why it went: the measurement that retired it.
`refuse_retired(schema, data, name)` walks YAML data the way the loader will read it into
`schema` and raises an InputError at the first retired key it meets.
"""

import typing

from corn_drake.config.yaml_io import field_types
from corn_drake.errors import InputError

# Each entry: the field as it stood, and the measurement that removed it (the project's own
# reports; docs/experiments_log.md has the rows).
RETIRED: dict[tuple[str, str], str] = {}


def retired_reason(schema, key: str) -> str | None:
    """Why `key` of config class `schema` was retired, or None where it was not."""
    name = getattr(schema, "__name__", None)
    return RETIRED.get((name, key)) if name else None


def retired_message(where: str, key: str, reason: str) -> str:
    return (f"{where}: {key} was retired ({reason}); remove it (a folder recorded with it still "
            "loads once the key is deleted from its config.yaml)")


def refuse_retired(schema, data, name: str, path: str = "") -> None:
    """InputError naming the first key of `data` (YAML read for `schema`, from `name`) that is
    a retired field."""
    if not isinstance(data, dict):
        return
    types = field_types(schema) or {}
    for key, value in data.items():
        dotted = f"{path}.{key}" if path else str(key)
        reason = retired_reason(schema, key)
        if reason is not None and key not in types:
            raise InputError(retired_message(name, dotted, reason))
        field_type = types.get(key)
        if field_type is None:
            continue
        if typing.get_origin(field_type) is typing.Union:  # a tagged variant (task.goal)
            variants = {v.__name__: v for v in typing.get_args(field_type)}
            tag = value.get("!") if isinstance(value, dict) else None
            field_type = variants.get(tag, typing.get_args(field_type)[0])
        if field_types(field_type) is not None:
            refuse_retired(field_type, value, name, dotted)
