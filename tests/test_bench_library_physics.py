"""`bench sim --objects`: bare-physics steps/s of every object of one or more libraries."""

import json
import math
import shutil

import numpy as np

from corn_drake.cli import main
from tests.fixtures import one_error_line, write_loadable_library


def test_each_object_is_measured_in_each_library_with_ratios_to_the_first(tmp_path):
    first = write_loadable_library(tmp_path / "a", num_train=1, num_unseen=2)
    second = tmp_path / "b"
    shutil.copytree(first, second)
    report = tmp_path / "objects.json"
    assert main(["bench", "sim", "--objects", str(first), str(second), "--steps", "20",
                 "--repeats", "1", "--report", str(report)]) == 0
    results = json.loads(report.read_text())["results"]
    objects = results["objects"]
    assert sorted(objects) == ["box_02", "cylinder_01"]  # the unseen split by default
    for row in objects.values():
        assert row["hulls"] == [1, 1] and all(r > 0 for r in row["bare_physics_policy_steps_per_s"])
        a, b = row["bare_physics_policy_steps_per_s"]
        assert row["ratio"] == [1.0, b / a]
    means = results["mean_bare_physics_policy_steps_per_s"]
    assert means[0] == np.mean([o["bare_physics_policy_steps_per_s"][0] for o in objects.values()])
    assert math.isclose(results["geometric_mean_ratio"][1],
                        math.sqrt(np.prod([o["ratio"][1] for o in objects.values()])))


def test_a_library_without_the_first_ones_objects_is_named(tmp_path, capsys):
    first = write_loadable_library(tmp_path / "a", num_train=1, num_unseen=2)
    other = write_loadable_library(tmp_path / "b", num_train=1, num_unseen=1)
    assert main(["bench", "sim", "--objects", str(first), str(other), "--steps", "20",
                 "--report", str(tmp_path / "r.json")]) == 2
    line = one_error_line(capsys)
    assert str(other) in line and "lacks 1 of" in line and "box_02" in line
    assert not (tmp_path / "r.json").exists()
