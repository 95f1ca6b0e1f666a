"""A run folder recorded with a value today's checks refuse is not poisoned (issue 53): the
corrected command resumes it, every other change is still refused, and NaN recorded and
requested counts as no change."""

import pytest

from corn_drake.config.plumbing.overrides import set_fields
from corn_drake.config.training import TrainConfig
from corn_drake.errors import InputError
from corn_drake.run_folders.config_file import write_run_config
from corn_drake.run_folders.guards import changed_arguments
from corn_drake.run_folders.resumable import ResumableRun, fields_refused_as_recorded


def _recorded(tmp_path, **values):
    cfg = set_fields(TrainConfig(), values, "test")
    write_run_config(cfg, tmp_path)  # as a run of an older version recorded it, unchecked
    return cfg


def _refuse(tmp_path, requested):
    with ResumableRun.open(tmp_path, TrainConfig) as run:
        run.refuse_changes(requested, may_grow=(), may_change=(), name=str)


def test_a_refused_recorded_value_may_be_corrected_on_resume(tmp_path):
    _recorded(tmp_path, **{"ppo.lr": float("nan")})
    _refuse(tmp_path, TrainConfig())  # the corrected command: accepted


def test_other_changes_are_still_refused_beside_the_correction(tmp_path):
    _recorded(tmp_path, **{"ppo.lr": float("nan")})
    requested = set_fields(TrainConfig(), {"seed": 7}, "test")
    with pytest.raises(InputError, match="seed: recorded 0, requested 7"):
        _refuse(tmp_path, requested)


def test_an_accepted_recorded_value_is_held_as_before(tmp_path):
    _recorded(tmp_path, **{"ppo.lr": 1e-4})
    with pytest.raises(InputError, match="ppo.lr"):
        _refuse(tmp_path, TrainConfig())


def test_only_the_fields_that_lift_the_refusal_are_taken():
    recorded = set_fields(TrainConfig(), {"ppo.lr": float("nan"), "ppo.gamma": 0.9}, "test")
    requested = TrainConfig()
    assert fields_refused_as_recorded(recorded, requested) == {"ppo.lr"}


def test_nan_recorded_and_nan_requested_is_no_change():
    assert changed_arguments({"a": float("nan"), "b": [1.0, float("nan")]},
                             {"a": float("nan"), "b": [1.0, float("nan")]}) == []
    assert changed_arguments({"a": float("nan")}, {"a": 0.5}) == ["a: recorded nan, requested 0.5"]
