"""Every setting is checked before anything is written (issue 53): each field of each config
dataclass in corn_drake.config declares its rule (config/plumbing/bounds.py), the rules and relations
are readable and name real fields, the hostile probes that once trained silently wrong or ended
in a traceback are refused in one line naming the key, and every shipped config still passes.
"""

from __future__ import annotations

import dataclasses as dc
import importlib
import inspect
import pkgutil
import types
import typing
from pathlib import Path

import pytest

import corn_drake
from corn_drake.cli import main
from corn_drake.config.plumbing.bounds import (check_bounds, check_spec, declared_bounds,
                                      declared_relations, describe, value_at, within)
from corn_drake.config.plumbing.diagram_files import available_tasks, load_teacher_config
from corn_drake.config.plumbing.loader import load_config
from corn_drake.config.plumbing.overrides import apply_sets
from corn_drake.config.primitive import PrimitiveTrainConfig
from corn_drake.config.training import DistillConfig, TrainConfig
from corn_drake.errors import InputError
from corn_drake.package_data import data_dir
from corn_drake.run_folders.config_file import run_kind
from tests.fixtures import one_error_line

# Dataclasses in corn_drake.config that are not configs a user sets (no YAML key reaches them).
NOT_CONFIGS = {"Change"}  # overrides.Change: what an override changed, for printing


def _config_classes() -> dict[str, type]:
    """Every dataclass of corn_drake.config, and every dataclass named *Config elsewhere in the
    package (the objects' and the contact data's settings live beside their code)."""
    classes = {}
    for module in pkgutil.walk_packages(corn_drake.__path__, "corn_drake."):
        in_config = module.name.startswith("corn_drake.config.")
        if "._data" in module.name or module.ispkg:
            continue
        mod = importlib.import_module(module.name)
        for name, obj in vars(mod).items():
            if (inspect.isclass(obj) and dc.is_dataclass(obj) and obj.__module__ == mod.__name__
                    and name not in NOT_CONFIGS and (in_config or name.endswith("Config"))):
                classes[obj.__qualname__] = obj
    return dict(sorted(classes.items()))


CLASSES = _config_classes()


def test_the_walk_finds_the_configs_outside_config():
    """Not vacuous: the settings that live beside their code are among the walked classes."""
    assert {"ProcessConfig", "DropConfig", "HullConfig", "DecompositionConfig",
            "ContactDataConfig", "TrainConfig"} <= set(CLASSES)
FIELDS = [(cls, field.name) for cls in CLASSES.values() for field in dc.fields(cls)]


def _is_union(kind) -> bool:
    return typing.get_origin(kind) in (typing.Union, types.UnionType)


def _exempt(kind) -> bool:
    """A bool (every value is valid), a nested config (its own fields are checked), or a tagged
    union of configs (each variant is a config class of its own, walked here too)."""
    if kind is bool or dc.is_dataclass(kind):
        return True
    return _is_union(kind) and all(dc.is_dataclass(k) for k in typing.get_args(kind))


@pytest.mark.parametrize("cls, name", FIELDS, ids=[f"{c.__name__}.{n}" for c, n in FIELDS])
def test_every_config_field_declares_a_rule(cls, name):
    kind = typing.get_type_hints(cls)[name]
    if _exempt(kind):
        return
    declared = declared_bounds(cls)
    # A field holding a Drake struct (PhysicsConfig.plant, CameraRigConfig.camera) declares the
    # struct's fields it relies on with dotted keys.
    assert name in declared or any(key.startswith(f"{name}.") for key in declared), (
        f"{cls.__name__}.{name} ({kind}) declares no rule in BOUNDS (config/plumbing/bounds.py lists "
        "them; free text is 'text')")


@pytest.mark.parametrize("cls", CLASSES.values(), ids=list(CLASSES))
def test_declared_rules_read_and_name_real_fields_and_defaults_pass(cls):
    default = cls()
    for key, spec in declared_bounds(cls).items():
        check_spec(spec)
        describe(spec)
        value_at(default, key)  # AttributeError: a rule left behind by a removed field
    for rel in declared_relations(cls):
        for key in (rel.subject, *rel.others):
            value_at(default, key)
            assert "{" + key + "}" in rel.rule or key == rel.subject, (rel, key)
    check_bounds(default)  # the defaults stay valid


def test_the_vocabulary_refuses_what_it_should():
    """The rules can fail: each one against a value it must refuse and one it must take."""
    rows = [("vector 3 > 0", [1, 2, 3], [1, float("nan"), 3]), ("vector 3 > 0", [1, 2, 3], [1, 2]),
            ("vector >= 0", [0.0], []), ("list vector 3 finite", [[0, 0, 1]], [[0, 0]]),
            ("one of a|b", "a", "c"), ("subset of a|b", ["b"], ["a", "a"]),
            ("seed", 2 ** 32 - 1, 2 ** 32), ("seed", 0, 1e23), ("seed", 1, True),
            ("text", "", None), ("device", "cuda:1", "gpu"), ("optional range > 0", None, [0.05, float("inf")]),
            ("finite", -3.0, float("inf"))]
    for spec, good, bad in rows:
        assert within(good, spec) and not within(bad, spec), (spec, good, bad)
    for bad_spec in (">0", "vector 3", "one of ", "[0, x]", "sometimes"):
        with pytest.raises(ValueError):
            check_spec(bad_spec)


# --- the hostile probes, through the real --set path ---------------------------------------------
# (schema, --set KEY=VALUE, the key the one-line refusal names, a word of its rule)
PROBES = [
    (TrainConfig, "ppo.lr_min=1", "ppo.lr_min", "<= ppo.lr"),
    (TrainConfig, "ppo.lr_max=1e-7", "ppo.lr", "<= ppo.lr_max"),
    (TrainConfig, "task.workspace_low=[1,1,1]", "task.workspace_low", "task.workspace_high"),
    (TrainConfig, "task.workspace_high=[0.5,0.55,0.39]", "task.workspace_low", "table"),
    (TrainConfig, "task.goal_x=[-0.3,0.1]", "task.goal_x", "table"),
    (TrainConfig, "task.robot_init_low=[0,0,0,0,0,0,.nan]", "task.robot_init_low", "finite"),
    (TrainConfig, "controller.effort_limits=[0,0,0,0,0,0,0]", "controller.effort_limits", "> 0"),
    (TrainConfig, "controller.torque_backend=foo", "controller.torque_backend", "symbolic"),
    (TrainConfig, "scene.object.size=[.nan,0.07,0.05]", "scene.object.size", "finite"),
    (TrainConfig, "scene.physics.plant.time_step=0", "scene.physics.plant.time_step", "> 0"),
    (TrainConfig, "scene.physics.policy_period=0.013", "scene.physics.policy_period",
     "whole number"),
    (TrainConfig, "scene.physics.plant.discrete_contact_approximation=sapp",
     "discrete_contact_approximation", "sap"),
    (TrainConfig, "scene.physics.compliant_body=foo", "scene.physics.compliant_body", "table"),
    (TrainConfig, "scene.physics.armature=[1,2]", "scene.physics.armature", "7"),
    (TrainConfig, "randomization.object_radius=[0.05,.inf]", "randomization.object_radius",
     "null or"),
    (TrainConfig, "seed=4294967296", "seed", "2**32"),
    (TrainConfig, "device=gpu", "device", "cuda"),
    (TrainConfig, "policy=cron", "policy", "corn"),
    (PrimitiveTrainConfig, "replay_capacity=4", "learning_starts", "replay_capacity"),
    (PrimitiveTrainConfig, "batch_size=300000", "batch_size", "[1, 65536]"),
    (DistillConfig, "frozen=[gru,gru]", "frozen", "distinct"),
    (DistillConfig, "cameras.eyes=[[0,0,0.45]]", "cameras.eyes", "away from"),
]


@pytest.mark.parametrize("schema, setting, key, rule", PROBES,
                         ids=[f"{s.__name__}:{p}" for s, p, _, _ in PROBES])
def test_a_contradicting_or_out_of_range_setting_is_refused_naming_its_key(schema, setting, key,
                                                                          rule):
    cfg = apply_sets(schema(), [setting])
    with pytest.raises(InputError) as refused:
        cfg.check()
    message = str(refused.value)
    assert len(message.splitlines()) == 1 and key in message and rule in message, message


@pytest.mark.parametrize("setting, key", [
    ("ppo.lr_min=1", "ppo.lr_min"),
    ("scene.physics.policy_period=0.013", "scene.physics.policy_period"),
    ("controller.effort_limits=[0,0,0,0,0,0,0]", "controller.effort_limits"),
])
def test_train_refuses_a_probe_in_one_line_before_writing(tmp_path, capsys, setting, key):
    out = tmp_path / "run"
    assert main(["train", "--policy", "state", "--set", setting, "--out", str(out)]) == 2
    one_error_line(capsys, key)
    assert not out.exists()


def test_train_primitive_refuses_a_replay_that_cannot_hold_a_batch(tmp_path, capsys):
    out = tmp_path / "run"
    encoder = str(data_dir("models") / "weights" / "push_corn" / "encoder.pt")
    assert main(["train", "--policy", "primitive", "--task", "push", "--encoder", encoder,
                 "--set", "replay_capacity=4", "--out", str(out)]) == 2
    one_error_line(capsys, "learning_starts", "replay_capacity")
    assert not out.exists()


@pytest.mark.parametrize("seed", ["1e23", str(2 ** 32), "-1"])
def test_train_refuses_a_seed_out_of_range_in_one_line(tmp_path, capsys, seed):
    out = tmp_path / "run"
    with pytest.raises(SystemExit) as exited:
        main(["train", "--policy", "state", "--seed", seed, "--out", str(out)])
    assert exited.value.code == 2
    one_error_line(capsys, "--seed", "2**32")
    assert not out.exists()


# --- the shipped configs still pass ----------------------------------------------------------------
SCHEMAS = {"train": TrainConfig, "distill": DistillConfig, "primitive": PrimitiveTrainConfig}
SHIPPED_RUNS = sorted((data_dir("models") / "weights").glob("*/config.yaml"))


@pytest.mark.parametrize("path", SHIPPED_RUNS, ids=[p.parent.name for p in SHIPPED_RUNS])
def test_every_shipped_run_config_passes_its_check(path: Path):
    load_config(SCHEMAS[run_kind(str(path.parent))], path).check()


@pytest.mark.parametrize("task", [None, *available_tasks()])
def test_every_shipped_diagram_and_task_passes_its_check(task):
    load_teacher_config(task).check()


def test_the_student_diagrams_pass_their_check():
    from corn_drake import DIAGRAMS_DIR
    from corn_drake.config.plumbing.diagram_files import load_student_config

    for path in sorted(DIAGRAMS_DIR.glob("student_rollout*.yaml")):
        load_student_config(path).check()
