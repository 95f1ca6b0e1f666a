"""Range checks and relations declared on the typed configs themselves: one mechanism for every
setting a user can give, in a YAML layer or with `--set`, checked before anything is written.

A config dataclass lists the rule of each of its fields in a class attribute (not a dataclass
field, so the YAML loader never sees it):

    BOUNDS = {"lr": "> 0", "episode_steps": ">= 1", "gamma": "(0, 1]", "mass": "range > 0"}

The rules (SPEC below is any number rule):
  "> x", ">= x", "< x", "<= x"   one finite number, compared with x
  "[a, b]", "(a, b]", ...        one finite number in the interval
  "finite"                       any finite number
  "range SPEC"                   a [low, high] pair with low <= high, each meeting SPEC
  "vector N SPEC"                a list of exactly N finite numbers, each meeting SPEC
  "vector SPEC"                  a list of one or more finite numbers, each meeting SPEC
  "list RULE"                    a list of one or more items, each meeting RULE (any rule)
  "one of a|b|c"                 one of these strings (build it from config/choices.py's tuples
                                 with one_of(), so the names are spelled once)
  "subset of a|b|c"              a list of distinct strings from the set (may be empty)
  "seed"                         an integer in [0, 2**32): numpy's and torch's seed range
  "device"                       a torch device name: cpu, cpu:N, cuda or cuda:N
  "text"                         free text (a path, an address, a name): declared explicitly, so
                                 a field is never left unchecked by forgetting it
  "optional RULE"                null, or RULE
Every number must be finite: NaN fails every comparison, so it is refused by the same check.

A key may be dotted to reach into a field that is not a config dataclass (Drake's
MultibodyPlantConfig in PhysicsConfig.plant): "plant.time_step": "> 0" declares the fields of
the Drake struct the project relies on, beside the field that holds it.

Relations between fields are declared beside them, in a class attribute RELATIONS: a tuple of
relation(subject, rule, holds, *others), e.g.

    RELATIONS = (relation("lr_min", "<= {lr}", lambda lr_min, lr: lr_min <= lr, "lr"),)

`holds` gets the values of the subject and the others (dotted keys, relative to the config),
in that order. A relation that spans sections (the workspace against the table) is declared on
the config that holds both. A refusal names the subject, its value and the rule, with every
other key written with its value:

    ppo.lr_min must be <= ppo.lr (0.0003), got 1.0

`check_bounds(cfg)` walks a config: its own BOUNDS, then every nested config (its bounds and
relations), then its own RELATIONS (so a relation sees fields already known to be in range),
and raises an InputError for the first violation, with its dotted path.
"""

import dataclasses as dc
import math
import operator
import re
from typing import Any, Callable, NamedTuple

from corn_drake.errors import InputError

_ONE_SIDED = {">": operator.gt, ">=": operator.ge, "<": operator.lt, "<=": operator.le}
_INTERVAL = re.compile(r"^([\[(])\s*(\S+)\s*,\s*(\S+)\s*([\])])$")
_DEVICE = re.compile(r"^(cpu|cuda)(:\d+)?$")
SEED_LIMIT = 2 ** 32  # numpy's SeedSequence takes more, but np.random.seed and Ray's do not


class Relation(NamedTuple):
    """A rule between fields of one config: `holds(subject's value, *others' values)`; `rule`
    says it after "SUBJECT must be ", with {KEY} standing for another key and its value."""
    subject: str
    rule: str
    holds: Callable[..., bool]
    others: tuple = ()


def relation(subject: str, rule: str, holds: Callable[..., bool], *others: str) -> Relation:
    return Relation(subject, rule, holds, others)


def one_of(names) -> str:
    """The "one of a|b|c" rule of a tuple of names (config/choices.py)."""
    return "one of " + "|".join(names)


def subset_of(names) -> str:
    return "subset of " + "|".join(names)


def _is_number(value) -> bool:
    return (not isinstance(value, bool) and isinstance(value, (int, float))
            and math.isfinite(value))


def _number_ok(value, spec: str) -> bool:
    if not _is_number(value):
        return False
    if spec == "finite":
        return True
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


def _vector(spec: str) -> tuple[int | None, str]:
    """(the length, or None for any length >= 1; the rule of each number) of a "vector" rule."""
    rest = spec.removeprefix("vector ")
    count, _, inner = rest.partition(" ")
    if count.isdigit():
        return int(count), inner
    return None, rest


def _names(spec: str, kind: str) -> list[str]:
    return spec.removeprefix(kind).split("|")


def within(value, spec: str) -> bool:
    """Whether `value` meets `spec` (the rules in this module's docstring)."""
    if spec.startswith("optional "):
        return value is None or within(value, spec.removeprefix("optional "))
    if spec.startswith("range "):
        inner = spec.removeprefix("range ")
        return (isinstance(value, (list, tuple)) and len(value) == 2
                and all(_number_ok(v, inner) for v in value) and value[0] <= value[1])
    if spec.startswith("vector "):
        count, inner = _vector(spec)
        return (isinstance(value, (list, tuple)) and len(value) >= 1
                and (count is None or len(value) == count)
                and all(_number_ok(v, inner) for v in value))
    if spec.startswith("list "):
        inner = spec.removeprefix("list ")
        return (isinstance(value, (list, tuple)) and len(value) >= 1
                and all(within(v, inner) for v in value))
    if spec.startswith("one of "):
        return isinstance(value, str) and value in _names(spec, "one of ")
    if spec.startswith("subset of "):
        return (isinstance(value, (list, tuple)) and len(set(value)) == len(value)
                and all(isinstance(v, str) and v in _names(spec, "subset of ") for v in value))
    if spec == "seed":
        return isinstance(value, int) and not isinstance(value, bool) and 0 <= value < SEED_LIMIT
    if spec == "device":
        return isinstance(value, str) and _DEVICE.match(value) is not None
    if spec == "text":
        return isinstance(value, str)
    return _number_ok(value, spec)


def describe(spec: str) -> str:
    """How a refusal states `spec`: 'a finite number > 0', '[low, high] with low <= high, each
    >= 0', 'one of fixed, tracking', ..."""
    if spec.startswith("optional "):
        return f"null or {describe(spec.removeprefix('optional '))}"
    if spec.startswith("range "):
        return f"[low, high] with low <= high, each {describe(spec.removeprefix('range '))}"
    if spec.startswith("vector "):
        count, inner = _vector(spec)
        each = "" if inner == "finite" else f", each {inner}"
        size = f"{count}" if count is not None else "one or more"
        return f"a list of {size} finite numbers{each}"
    if spec.startswith("list "):
        return f"a list of one or more items, each {describe(spec.removeprefix('list '))}"
    if spec.startswith("one of "):
        return f"one of {', '.join(_names(spec, 'one of '))}"
    if spec.startswith("subset of "):
        return f"a list of distinct names from {', '.join(_names(spec, 'subset of '))}"
    if spec == "seed":
        return "an integer in [0, 2**32)"
    if spec == "device":
        return "cpu, cpu:N, cuda or cuda:N"
    if spec == "text":
        return "a string"
    if spec == "finite":
        return "a finite number"
    if _INTERVAL.match(spec):
        return f"a finite number in {spec}"
    return f"a finite number {spec}"


def check_spec(spec: str) -> None:
    """ValueError for a rule this module cannot read (a typo in a BOUNDS table would otherwise
    surface only when a value reaches it)."""
    for prefix in ("optional ", "list "):
        if spec.startswith(prefix):
            return check_spec(spec.removeprefix(prefix))
    if spec.startswith("range "):
        return _check_number_spec(spec.removeprefix("range "), spec)
    if spec.startswith("vector "):
        return _check_number_spec(_vector(spec)[1], spec)
    for kind in ("one of ", "subset of "):
        if spec.startswith(kind):
            if not all(_names(spec, kind)):
                raise ValueError(f"bad bound spec {spec!r}")
            return None
    if spec in ("seed", "device", "text"):
        return None
    return _check_number_spec(spec, spec)


def _check_number_spec(inner: str, spec: str) -> None:
    try:
        _number_ok(0.0, inner)  # parses the bound(s); ValueError for a rule it cannot read
    except ValueError:
        raise ValueError(f"bad bound spec {spec!r}") from None


def declared_bounds(cls: type) -> dict[str, str]:
    """{field or dotted key: rule} of a config class, its bases' included (a subclass adds to,
    or overrides, its bases' bounds)."""
    declared = {}
    for base in reversed(cls.__mro__):
        declared.update(vars(base).get("BOUNDS", {}))
    return declared


def declared_relations(cls: type) -> list[Relation]:
    """The relations of a config class, its bases' first."""
    relations = []
    for base in reversed(cls.__mro__):
        relations.extend(vars(base).get("RELATIONS", ()))
    return relations


def value_at(cfg: Any, key: str) -> Any:
    """The value of a dotted key of `cfg` ("plant.time_step")."""
    for part in key.split("."):
        cfg = getattr(cfg, part)
    return cfg


def check_relations(cfg, prefix: str = "") -> None:
    """InputError naming the first relation of `cfg` (its own, not its nested configs') that
    does not hold."""
    for rel in declared_relations(type(cfg)):
        values = [value_at(cfg, rel.subject), *(value_at(cfg, k) for k in rel.others)]
        if rel.holds(*values):
            continue
        rule = rel.rule
        for key, value in zip(rel.others, values[1:]):
            rule = rule.replace("{" + key + "}", f"{prefix}{key} ({value!r})")
        raise InputError(f"{prefix}{rel.subject} must be {rule}, got {values[0]!r}")


def check_bounds(cfg, prefix: str = "") -> None:
    """InputError naming the first field of `cfg` (a config dataclass) or of a config nested in
    it whose value breaks the rule its class declares, or the first relation that fails."""
    if not dc.is_dataclass(cfg):
        return
    for name, spec in declared_bounds(type(cfg)).items():
        value = value_at(cfg, name)
        if not within(value, spec):
            raise InputError(f"{prefix}{name} must be {describe(spec)}, got {value!r}")
    for field in dc.fields(cfg):
        value = getattr(cfg, field.name)
        if dc.is_dataclass(value):
            check_bounds(value, f"{prefix}{field.name}.")
    check_relations(cfg, prefix)
