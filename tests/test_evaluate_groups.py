"""The evaluation report's success per object group (new families, new members, train)."""

import json

import pytest

from corn_drake.assets.library import object_groups
from corn_drake.evaluation.episodes import success_by_group
from corn_drake.errors import InputError
from tests.fixtures import write_tiny_library


def _rows(outcomes):
    return [{"episode": k, "object": o, "success": s} for k, (o, s) in enumerate(outcomes)]


def test_success_is_aggregated_per_group():
    groups = {"bottle_000": "family", "wedge_000": "family", "cuboid_004": "member",
              "mesh_bunny": "ingested"}
    rows = _rows([("bottle_000", True), ("wedge_000", False), ("cuboid_004", True),
                  ("bottle_000", True), ("cuboid_004", False), ("mesh_bunny", False)])
    assert success_by_group(rows, groups) == {
        "family": {"success_rate": 2 / 3, "episodes": 3, "objects": 2},
        "ingested": {"success_rate": 0.0, "episodes": 1, "objects": 1},
        "member": {"success_rate": 0.5, "episodes": 2, "objects": 1}}


def test_an_object_without_a_group_is_named():
    with pytest.raises(InputError, match="teapot"):
        success_by_group(_rows([("teapot", True)]), {"cuboid_000": "member"})


def test_groups_come_from_the_manifest(tmp_path):
    lib = write_tiny_library(tmp_path / "lib")
    # A library written before unseen groups existed: its unseen objects fall back to "unseen".
    assert object_groups(lib) == {"box_a": "train", "box_b": "train", "cyl_a": "train",
                                  "cyl_u": "unseen"}
    manifest = json.loads((lib / "manifest.json").read_text())
    manifest["objects"][3]["unseen_group"] = "member"
    (lib / "manifest.json").write_text(json.dumps(manifest))
    assert object_groups(lib)["cyl_u"] == "member"


def test_evaluate_on_a_library_reports_success_by_group(tmp_path):
    from corn_drake.assets.library import build_procedural
    from corn_drake.assets.processing.process import ProcessConfig
    from corn_drake.cli import main

    cfg = ProcessConfig()
    cfg.drops.drops = 6
    lib = tmp_path / "lib"
    build_procedural(lib, 3, seed=0, cfg=cfg, progress=False)  # block, book, bottle (unseen)
    report = tmp_path / "eval.json"
    assert main(["evaluate", "--run", "still", "--objects", str(lib), "--split", "all",
                 "--task", "push",
                 "--episodes", "3", "--record", "0", "--report", str(report)]) == 0
    data = json.loads(report.read_text())
    assert data["success_by_group"] == {
        "family": {"success_rate": 0.0, "episodes": 1, "objects": 1},
        "train": {"success_rate": 0.0, "episodes": 2, "objects": 2}}
    for key in ("success_rate", "balanced_success_rate", "per_object", "episodes"):
        assert key in data  # the report keeps its keys
    # ...and says which task and action step it was run on.
    assert (data["task"], data["action_step"]) == ("push", 0.03)


def test_evaluate_names_the_objects_its_split_leaves_out(tmp_path, capsys):
    """A library of one's own is split too: evaluating its unseen objects says which of the
    others it skipped, and --split all skips none."""
    from corn_drake.cli import main
    from tests.fixtures import write_loadable_library

    lib = write_loadable_library(tmp_path / "lib", 2, 1)
    common = ["evaluate", "--run", "still", "--objects", str(lib), "--task", "push",
              "--episodes", "1", "--record", "0", "--no-progress"]
    assert main([*common, "--report", str(tmp_path / "a.json")]) == 0
    said = capsys.readouterr().out
    assert "1 unseen objects of" in said and "'s 3; skipped" in said
    assert "box_00" in said and "cylinder_01" in said and "--split all" in said
    assert main([*common, "--split", "all", "--report", str(tmp_path / "b.json")]) == 0
    assert "skipped" not in capsys.readouterr().out
