"""Hostile mesh inputs: each becomes a clear rejection or a repaired object, never a crash."""

import json

import numpy as np
import pytest
import trimesh

from corn_drake.assets.library import ingest_folder
from corn_drake.assets.processing.process import ProcessConfig


@pytest.fixture(scope="module")
def ingested(tmp_path_factory):
    src = tmp_path_factory.mktemp("meshes")
    (src / "empty.obj").write_text("")
    (src / "garbage.stl").write_bytes(bytes(range(256)) * 7)
    (src / "triangle.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    box = trimesh.creation.box([0.06, 0.05, 0.04])
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-2])  # two faces missing
    open_box.export(src / "open_box.ply")
    nan = box.copy()
    nan.vertices[0] = [np.nan, 0, 0]
    (src / "nan.obj").write_text(trimesh.exchange.obj.export_obj(nan))
    trimesh.creation.box([600.0, 500.0, 400.0]).export(src / "huge.off")  # ~1e4x too large
    two = trimesh.util.concatenate([trimesh.creation.box([0.05] * 3),
                                    trimesh.creation.icosphere(radius=0.01).apply_translation([0.2, 0, 0])])
    (src / "sub").mkdir()
    two.export(src / "sub" / "two_bodies.obj")
    (src / "notes.txt").write_text("not a mesh")
    cfg = ProcessConfig()
    cfg.drops.drops = 8
    manifest = ingest_folder(src, src.parent / "lib", cfg=cfg, progress=False)
    return manifest


def _reason(manifest, name):
    return next((r.reason for r in manifest.rejected if r.source.endswith(name)), None)


def _object(manifest, name):
    return next((o for o in manifest.objects if o.source.endswith(name)), None)


def test_unusable_inputs_are_rejected_with_reasons(ingested):
    assert "empty" in _reason(ingested, "empty.obj")
    assert _reason(ingested, "garbage.stl") is not None
    assert "triangles" in _reason(ingested, "triangle.obj")
    assert "non-finite" in _reason(ingested, "nan.obj")
    assert "unsupported extension" in _reason(ingested, "notes.txt")


def test_repairable_inputs_become_objects_with_warnings(ingested):
    huge = _object(ingested, "huge.off")
    assert huge and any("rescaled" in w for w in huge.warnings)
    assert 0.05 <= huge.radius <= 0.10
    two = _object(ingested, "two_bodies.obj")
    assert two and any("largest" in w for w in two.warnings)
    open_box = _object(ingested, "open_box.ply")
    assert open_box is not None and open_box.num_stable_poses > 0
    # Everything that was not rejected is a complete object.
    for o in ingested.objects:
        assert o.num_stable_poses > 0 and o.hulls
    assert len(ingested.objects) + len(ingested.rejected) == 8  # every input accounted for
