"""Tiny object libraries for tests, written in the library's manifest format."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from corn_drake.scene.objects import box_spec, cylinder_spec


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
