"""Settings retired because they measured no gain (config/retired.py): a run folder whose
config.yaml names one, or a `--set` naming one, is refused in one line that names the key and
says it was retired, for every key in the registry."""

import typing

import pytest

from corn_drake.config.plumbing.overrides import apply_sets
from corn_drake.config.primitive import PrimitiveTrainConfig
from corn_drake.config.retired import RETIRED
from corn_drake.config.training import DistillConfig, TrainConfig
from corn_drake.config.plumbing.yaml_io import dump_tagged_yaml, field_types, read_tagged_yaml
from corn_drake.errors import InputError


def _load_primitive_folder(folder):
    from corn_drake.rl.primitive.agent import load_primitive_run

    return load_primitive_run(folder)  # reads config.yaml before any checkpoint


def _load_train_folder(folder):
    from corn_drake.run_folders.config_file import load_run_config

    return load_run_config(folder)


def _load_distill_folder(folder):
    from corn_drake.config.plumbing.loader import load_config
    from corn_drake.run_folders.config_file import run_config_path

    return load_config(DistillConfig, run_config_path(folder))


# The run configs a folder holds, each with how a command reads that folder's config.yaml.
ROOTS = {PrimitiveTrainConfig: _load_primitive_folder, TrainConfig: _load_train_folder,
         DistillConfig: _load_distill_folder}


def _sections(schema, path=()):
    """(section path, config class) of `schema` and every config nested in it."""
    yield path, schema
    for name, kind in (field_types(schema) or {}).items():
        if typing.get_origin(kind) is typing.Union:  # a tagged variant: each member
            for member in typing.get_args(kind):
                if field_types(member) is not None:
                    yield from _sections(member, (*path, name))
        elif field_types(kind) is not None:
            yield from _sections(kind, (*path, name))


def _where(class_name: str):
    """(root config, dotted path of the section) of the first run config holding a section of
    class `class_name`."""
    for root in ROOTS:
        for path, schema in _sections(root):
            if schema.__name__ == class_name:
                return root, path
    raise AssertionError(f"no run config has a section of class {class_name}")


CASES = sorted(RETIRED)


@pytest.mark.parametrize("class_name, key", CASES, ids=[f"{c}.{k}" for c, k in CASES])
def test_a_retired_key_is_refused_in_a_run_folder_and_by_set(tmp_path, class_name, key):
    from pydrake.common.yaml import yaml_dump_typed

    root, path = _where(class_name)
    dotted = ".".join((*path, key))
    # The root's full config as a run writes it, with the retired key where it used to be.
    data = read_tagged_yaml(yaml_dump_typed(root()))
    section = data
    for part in path:
        section = section[part]
    assert key not in section, f"{class_name}.{key} is registered as retired but still a field"
    section[key] = 0
    (tmp_path / "config.yaml").write_text(dump_tagged_yaml(data))
    with pytest.raises(InputError) as refused:
        ROOTS[root](tmp_path)
    message = str(refused.value)
    assert "\n" not in message and dotted in message and "retired" in message, message

    with pytest.raises(InputError) as refused:
        apply_sets(root(), [f"{dotted}=0"])
    message = str(refused.value)
    assert "\n" not in message and dotted in message and "retired" in message, message
    assert message.startswith(f"--set {dotted}=0:"), message


def test_an_agent_checkpoint_of_retired_point_locations_is_refused():
    """A checkpoint written by a run of cloud-point locations (before they were retired) names
    them: loading it into the patch agent is refused rather than misread."""
    from corn_drake.nn.encoders.encoder_files import make_policy_encoder
    from corn_drake.rl.primitive.agent import PrimitiveAgent

    agent = PrimitiveAgent(make_policy_encoder("corn"), hidden=32)
    state = agent.network_state()
    agent.load_network_state({**state, "locations": "patch", "point_locations": 64}, "old")
    with pytest.raises(InputError, match="old: a primitive agent of 'point' locations, which "
                                         "were retired"):
        agent.load_network_state({**state, "locations": "point"}, "old")
    with pytest.raises(InputError, match="hidden 32, not hidden 64"):
        PrimitiveAgent(make_policy_encoder("corn"), hidden=64).load_network_state(state, "old")
