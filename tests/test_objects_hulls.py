"""Hull files Drake loads as rigid and as compliant hydroelastic geometry, and can touch things."""

import json

import numpy as np
import pytest
import trimesh
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from corn_drake.assets.processing.hulls import (HullConfig, drake_hull_problem, loadable_hull,
                                                obj_text)
from corn_drake.assets.ingest import Rejected
from corn_drake.assets.processing.process import loadable_hulls
from corn_drake.assets.processing.stable_poses import _rotation_taking
from corn_drake.config.scene import SceneConfig
from corn_drake.scene.builder import build_table_scene
from corn_drake.scene.objects import TABLE_TOP_Z, ObjectSpec

CORNER = np.array([0.03, 0.02, 0.015])


def _corner_cluster_hull() -> trimesh.Trimesh:
    """A box whose corner is a cluster of three vertices within ~0.2 um, as a decomposition's
    cut passing next to a vertex leaves; the hull of those points has a face of ~1e-14 m^2."""
    box = trimesh.creation.box(2 * CORNER).vertices
    cluster = CORNER + 1e-7 * np.random.default_rng(4).normal(size=(2, 3))
    return trimesh.convex.convex_hull(np.vstack([box, cluster]))


def _drop_corner_down(path) -> None:
    """Lets the hull, compliant, fall 1 mm onto the rigid table with CORNER lowest."""
    cfg = SceneConfig()
    cfg.physics.compliant_body, cfg.physics.time_step = "object", 0.001
    spec = ObjectSpec(name="hull", mass=0.1, unit_inertia=np.eye(3) * 1e-4, com=np.zeros(3),
                      cloud=np.zeros((1, 6)), stable_poses=np.zeros((0, 7)), radius=0.04,
                      bbox_corners=np.zeros((8, 3)), hull_paths=[path])
    builder = DiagramBuilder()
    plant, _, body = build_table_scene(builder, cfg, spec)
    sim = Simulator(builder.Build())
    R = _rotation_taking(CORNER / np.linalg.norm(CORNER), np.array([0.0, 0.0, -1.0]))
    plant.SetFreeBodyPose(plant.GetMyMutableContextFromRoot(sim.get_mutable_context()), body,
                          RigidTransform(RotationMatrix(R),
                                         [0, 0, TABLE_TOP_Z + np.linalg.norm(CORNER) + 0.001]))
    sim.AdvanceTo(0.3)


def test_a_degenerate_hull_is_caught_and_repaired_before_drake_meets_it(tmp_path):
    hull = _corner_cluster_hull()
    raw = tmp_path / "raw.obj"
    raw.write_text(obj_text(hull))  # what the library wrote before hulls were checked
    # Drake registers it, then throws once the degenerate face touches the table.
    with pytest.raises(RuntimeError, match="Cannot instantiate plane from normal"):
        _drop_corner_down(raw)
    assert "degenerate face" in drake_hull_problem(raw)

    text, repaired, note = loadable_hull(hull)
    assert text is not None and "repaired" in note
    fixed = tmp_path / "fixed.obj"
    fixed.write_text(text)
    assert drake_hull_problem(fixed) is None
    _drop_corner_down(fixed)  # no exception
    assert repaired.volume == pytest.approx(hull.volume, rel=1e-4)  # the repair moved < 10 um


def test_a_hull_nothing_repairs_is_dropped_and_an_object_of_only_such_hulls_rejected():
    flat = trimesh.convex.convex_hull(trimesh.creation.box([0.05, 0.04, 1e-8]).vertices)
    text, _, note = loadable_hull(flat)
    assert text is None and note.startswith("dropped")
    good = trimesh.creation.box([0.05, 0.04, 0.03])
    kept, repairs, dropped = loadable_hulls([good, flat], HullConfig())
    assert len(kept) == 1 and repairs == [] and len(dropped) == 1 and "piece 1" in dropped[0]
    with pytest.raises(Rejected, match="no convex hull Drake can load"):
        loadable_hulls([flat], HullConfig())


def _blob() -> trimesh.Trimesh:
    """A lumpy, non-convex closed surface (a stand-in for a scanned object)."""
    sphere = trimesh.creation.icosphere(3, 1.0)
    v = sphere.vertices
    theta, phi = np.arctan2(v[:, 1], v[:, 0]), np.arccos(np.clip(v[:, 2], -1, 1))
    radius = 1 + 0.3 * np.sin(3 * theta) * np.sin(phi) ** 2 + 0.2 * np.cos(2 * phi)
    return trimesh.Trimesh(v * radius[:, None] * [0.06, 0.04, 0.035], sphere.faces)


@pytest.mark.slow
def test_objects_command_on_real_meshes_writes_only_loadable_hulls(tmp_path, capsys):
    from corn_drake.cli import main

    src = tmp_path / "meshes"
    src.mkdir()
    trimesh.creation.torus(0.05, 0.015).export(src / "torus.obj")
    blob = _blob()
    assert blob.is_watertight and blob.volume < 0.95 * blob.convex_hull.volume  # non-convex
    blob.export(src / "blob.obj")
    (src / "corner_cluster.obj").write_text(obj_text(_corner_cluster_hull()))
    out = tmp_path / "lib"
    assert main(["objects", "--source", str(src), "--out", str(out), "--drops", "8",
                 "--no-progress"]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert sorted(o["id"] for o in manifest["objects"]) == ["mesh_blob", "mesh_corner_cluster",
                                                           "mesh_torus"]
    for o in manifest["objects"]:
        assert o["hulls"]
        for h in o["hulls"]:
            assert drake_hull_problem(out / h) is None, (o["id"], h)
    # Nothing else that looks like a hull was left in the library either.
    written = sorted(p.relative_to(out).as_posix() for p in out.glob("*/hull_*.obj"))
    assert written == sorted(h for o in manifest["objects"] for h in o["hulls"])
    cluster = next(o for o in manifest["objects"] if o["id"] == "mesh_corner_cluster")
    assert any("repaired" in r for r in cluster["hull_repairs"])
    # Each object reports the share of its training-setting poses the second setting kept.
    for o in manifest["objects"]:
        d = o["drops"]
        assert o["stable_pose_kept_fraction"] == d["held_second_setting"] / d["verified"]
        assert d["held_second_setting"] == o["num_stable_poses"] > 0
    assert "stable poses holding under both contact settings" in capsys.readouterr().out
