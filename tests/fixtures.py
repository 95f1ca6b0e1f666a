"""Tiny object libraries for tests, written in the library's manifest format."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from corn_drake.scene.objects import ObjectSpec, box_spec, cylinder_spec


def write_tiny_library(root: Path) -> Path:
    """Three train primitives and one unseen, clouds only (what the contact data reads)."""
    specs = {"box_a": ("train", box_spec([0.1, 0.06, 0.04], 0.2, seed=1)),
             "box_b": ("train", box_spec([0.05, 0.05, 0.12], 0.2, seed=2)),
             "cyl_a": ("train", cylinder_spec(0.03, 0.1, 0.2, seed=3)),
             "cyl_u": ("unseen", cylinder_spec(0.05, 0.04, 0.2, seed=4))}
    root.mkdir(parents=True, exist_ok=True)
    objects = []
    for oid, (split, spec) in specs.items():
        np.save(root / f"{oid}_cloud.npy", spec.cloud)
        objects.append({"id": oid, "source": "fixture", "family": spec.primitive[0], "split": split,
                        "radius": spec.radius, "mass": spec.mass, "thin": spec.thin, "hulls": [],
                        "visual": "", "cloud": f"{oid}_cloud.npy", "stable_poses": ""})
    (root / "manifest.json").write_text(json.dumps({"objects": objects, "rejected": []}))
    return root


def _primitive_mesh(spec: ObjectSpec):
    """The primitive as a triangle mesh (a 16-sided prism for a cylinder): one convex hull."""
    import trimesh

    kind, dims = spec.primitive
    if kind == "box":
        return trimesh.creation.box(extents=dims)
    radius, length = dims
    return trimesh.creation.cylinder(radius=radius, height=length, sections=16)


def write_loadable_library(root: Path, num_train: int, num_unseen: int = 1) -> Path:
    """`num_train` train and `num_unseen` unseen primitives (boxes and cylinders of varied
    sizes) that TeacherEnv can load: one hull each, stable poses, keypoints, inertia. Cheap to
    write (no decomposition, no drops): the primitives' stable poses are known in closed form."""
    import trimesh

    root.mkdir(parents=True, exist_ok=True)
    objects = []
    for i in range(num_train + num_unseen):
        split = "train" if i < num_train else "unseen"
        if i % 2 == 0:
            spec = box_spec([0.06 + 0.005 * i, 0.05, 0.04 + 0.003 * i], 0.2, seed=i)
        else:
            spec = cylinder_spec(0.025 + 0.002 * i, 0.06, 0.2, seed=i)
        oid = f"{spec.primitive[0]}_{i:02d}"
        folder = root / oid
        folder.mkdir(exist_ok=True)
        mesh_text = trimesh.exchange.obj.export_obj(_primitive_mesh(spec), include_normals=False,
                                                    include_texture=False)
        (folder / "hull_00.obj").write_text(mesh_text)
        (folder / "visual.obj").write_text(mesh_text)
        for name, array in (("cloud", spec.cloud), ("stable_poses", spec.stable_poses),
                            ("bbox_corners", spec.bbox_corners), ("unit_inertia", spec.unit_inertia)):
            np.save(folder / f"{name}.npy", array)
        objects.append({"id": oid, "source": "fixture", "family": spec.primitive[0], "split": split,
                        "radius": spec.radius, "mass": spec.mass, "thin": spec.thin,
                        "hulls": [f"{oid}/hull_00.obj"], "visual": f"{oid}/visual.obj",
                        "cloud": f"{oid}/cloud.npy", "stable_poses": f"{oid}/stable_poses.npy",
                        "bbox_corners": f"{oid}/bbox_corners.npy",
                        "unit_inertia": f"{oid}/unit_inertia.npy"})
    (root / "manifest.json").write_text(json.dumps({"objects": objects, "rejected": []}))
    return root


def one_error_line(capsys, *needles: str) -> str:
    """The captured stderr of a refused command: one line, no traceback, holding each of
    `needles` (the flag or file it names); returned for further checks."""
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, (needle, err)
    return err
