"""Range checks declared on the typed configs themselves: one mechanism for every number a user can
set, in a YAML layer or with `--set`.

A config dataclass lists its bounded fields in a class attribute (not a dataclass field, so the
YAML loader never sees it):

    BOUNDS = {"lr": "> 0", "episode_steps": ">= 1", "gamma": "(0, 1]", "mass": "range > 0"}

"> x", ">= x", "< x", "<= x": one number; "[a, b]", "(a, b]", "[a, b)", "(a, b)": an interval;
"range SPEC": a [low, high] pair with low <= high, each end within SPEC. Every bounded number
must also be finite (NaN fails every comparison, so it is refused by the same check).
`check_bounds(cfg)` walks a config and its nested configs and raises an InputError naming the
first field out of its bounds, with its dotted path.
"""

import dataclasses as dc
import math
import operator
import re

from corn_drake.errors import InputError

_ONE_SIDED = {">": operator.gt, ">=": operator.ge, "<": operator.lt, "<=": operator.le}
_INTERVAL = re.compile(r"^([\[(])\s*(\S+)\s*,\s*(\S+)\s*([\])])$")


def _number_ok(value, spec: str) -> bool:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return False
    interval = _INTERVAL.match(spec)
    if interval:
        open_low, low, high, open_high = interval.groups()
        low, high = float(low), float(high)
        above = value > low if open_low == "(" else value >= low
        below = value < high if open_high == ")" else value <= high
        return above and below
    op, _, bound = spec.partition(" ")
    if op not in _ONE_SIDED:
        raise ValueError(f"bad bound spec {spec!r}")  # a programming error in a BOUNDS table
    return _ONE_SIDED[op](value, float(bound))


def within(value, spec: str) -> bool:
    """Whether `value` meets `spec` (the syntax in this module's docstring)."""
    if spec.startswith("range "):
        inner = spec.removeprefix("range ")
        return (isinstance(value, (list, tuple)) and len(value) == 2
                and all(_number_ok(v, inner) for v in value) and value[0] <= value[1])
    return _number_ok(value, spec)


def describe(spec: str) -> str:
    """How a refusal states `spec`: 'a finite number > 0', '[low, high] with low <= high, each
    >= 0', ..."""
    if spec.startswith("range "):
        return f"[low, high] with low <= high, each {describe(spec.removeprefix('range '))}"
    if _INTERVAL.match(spec):
        return f"a finite number in {spec}"
    return f"a finite number {spec}"


def check_bounds(cfg, prefix: str = "") -> None:
    """InputError naming the first field of `cfg` (a config dataclass) or of a config nested in
    it whose value is outside the bounds its class declares."""
    if not dc.is_dataclass(cfg):
        return
    declared = {}
    for cls in reversed(type(cfg).__mro__):  # a subclass adds to (or overrides) its bases' bounds
        declared.update(vars(cls).get("BOUNDS", {}))
    for name, spec in declared.items():
        value = getattr(cfg, name)
        if not within(value, spec):
            raise InputError(f"{prefix}{name} must be {describe(spec)}, got {value!r}")
    for field in dc.fields(cfg):
        value = getattr(cfg, field.name)
        if dc.is_dataclass(value):
            check_bounds(value, f"{prefix}{field.name}.")
