"""Procedural object families (manifold3d solids), each parameterised and seeded.

Fourteen families span what the paper's DexGraspNet objects show: cuboids of any aspect ratio,
thin plates and books, cylinders and bottles, cones and frusta, spheres and eggs (rollers),
capsules, mugs with handles and bowls (concave), L/T/U blocks, wedges, random convex hulls and
toy-like unions of primitives. Every generator returns a watertight manifold in metres, roughly
0.05-0.2 m across; the library normalises scale afterwards.
"""

from __future__ import annotations

from typing import Callable

import manifold3d as mf
import numpy as np
import trimesh

Rng = np.random.Generator
SEGMENTS = 32  # circle resolution: enough for contact, few triangles for CoACD
# Hollow shapes (cup and bowl walls, the mug's handle): an n-gon wall splits into n exact convex
# pieces, so 10 sides keep a mug or bowl within the 16-hull budget with its hull union near the
# mesh volume (32-sided walls left CoACD at 1.16-1.34x the mesh volume).
SHELL_SEGMENTS = 10
HANDLE_SEGMENTS = 8


def _box(x, y, z) -> mf.Manifold:
    return mf.Manifold.cube([x, y, z], center=True)


def _cyl(r, h, r_top=None, segments=SEGMENTS) -> mf.Manifold:
    return mf.Manifold.cylinder(h, r, r if r_top is None else r_top, segments, center=True)


def cuboid(rng: Rng):
    return _box(*rng.uniform(0.04, 0.16, 3))


def plate(rng: Rng):  # thin: yaw-only goals
    return _box(rng.uniform(0.10, 0.18), rng.uniform(0.06, 0.14), rng.uniform(0.008, 0.02))


def book(rng: Rng):
    x, y, z = rng.uniform(0.12, 0.18), rng.uniform(0.09, 0.13), rng.uniform(0.025, 0.045)
    cover = _box(x, y, z)
    groove = _box(x * 1.1, y * 0.9, z * 0.1).translate([0, 0, z * 0.25])
    return cover - groove.translate([0, 0.02 * y, 0])


def cylinder(rng: Rng):
    return _cyl(rng.uniform(0.02, 0.06), rng.uniform(0.04, 0.16))


def bottle(rng: Rng):
    r, h = rng.uniform(0.025, 0.04), rng.uniform(0.08, 0.14)
    neck_r, neck_h = r * rng.uniform(0.35, 0.5), h * rng.uniform(0.25, 0.4)
    body = _cyl(r, h)
    shoulder = _cyl(r, 0.3 * neck_h, neck_r).translate([0, 0, h / 2 + 0.15 * neck_h])
    neck = _cyl(neck_r, neck_h).translate([0, 0, h / 2 + 0.3 * neck_h + neck_h / 2 - 0.001])
    return body + shoulder + neck


def frustum(rng: Rng):
    r = rng.uniform(0.03, 0.07)
    return _cyl(r, rng.uniform(0.04, 0.12), r * rng.uniform(0.0, 0.7))


def ellipsoid(rng: Rng):  # spheres and eggs: rollers
    return mf.Manifold.sphere(1.0, SEGMENTS).scale(rng.uniform(0.025, 0.06, 3))


def capsule(rng: Rng):
    r, h = rng.uniform(0.02, 0.04), rng.uniform(0.04, 0.12)
    ball = mf.Manifold.sphere(r, SEGMENTS)
    return _cyl(r, h) + ball.translate([0, 0, h / 2]) + ball.translate([0, 0, -h / 2])


def mug(rng: Rng):
    r, h = rng.uniform(0.03, 0.05), rng.uniform(0.06, 0.11)
    wall = rng.uniform(0.004, 0.008)
    cup = (_cyl(r, h, segments=SHELL_SEGMENTS)
           - _cyl(r - wall, h, segments=SHELL_SEGMENTS).translate([0, 0, wall]))
    handle_r = rng.uniform(0.35, 0.45) * h
    ring = (mf.Manifold.cylinder(0.012, handle_r, handle_r, HANDLE_SEGMENTS, center=True)
            - mf.Manifold.cylinder(0.013, handle_r - 0.008, handle_r - 0.008, HANDLE_SEGMENTS,
                                   center=True))
    ring = ring.rotate([90, 0, 0]) - _box(2 * handle_r, 0.02, 2 * handle_r).translate([-handle_r, 0, 0])
    return cup + ring.translate([r - 0.002, 0, 0])


def bowl(rng: Rng):  # bowls and drippers: a flat-bottomed conical shell
    r_top, h = rng.uniform(0.05, 0.08), rng.uniform(0.03, 0.06)
    r_bottom = r_top * rng.uniform(0.4, 0.7)
    wall = rng.uniform(0.005, 0.01)
    outer = _cyl(r_bottom, h, r_top, segments=SHELL_SEGMENTS)
    inner = _cyl(r_bottom - wall, h, r_top - wall, segments=SHELL_SEGMENTS).translate([0, 0, wall])
    return outer - inner


def block(rng: Rng):  # L, T and U shapes
    w, t, d = rng.uniform(0.08, 0.14), rng.uniform(0.02, 0.04), rng.uniform(0.03, 0.06)
    bar = _box(w, t, d)
    leg = _box(t, rng.uniform(0.05, 0.1), d)
    shape = rng.integers(3)
    if shape == 0:  # L
        return bar + leg.translate([-(w - t) / 2, leg.bounding_box()[4], 0])
    if shape == 1:  # T
        return bar + leg.translate([0, leg.bounding_box()[4], 0])
    arm = leg.translate([0, leg.bounding_box()[4], 0])  # U
    return bar + arm.translate([-(w - t) / 2, 0, 0]) + arm.translate([(w - t) / 2, 0, 0])


def wedge(rng: Rng):
    x, y, z = rng.uniform(0.06, 0.14), rng.uniform(0.04, 0.1), rng.uniform(0.03, 0.08)
    top = rng.uniform(0.0, 0.4) * x
    pts = np.array([[-x / 2, -y / 2, 0], [x / 2, -y / 2, 0], [-x / 2, y / 2, 0], [x / 2, y / 2, 0],
                    [-x / 2, -y / 2, z], [-x / 2 + top, -y / 2, z], [-x / 2, y / 2, z], [-x / 2 + top, y / 2, z]])
    return mf.Manifold.hull_points(pts)


def convex_hull(rng: Rng):
    pts = rng.normal(size=(rng.integers(8, 24), 3)) * rng.uniform(0.02, 0.05, 3)
    return mf.Manifold.hull_points(pts)


def toy(rng: Rng):  # unions of a few primitives, toy-like
    parts = []
    for _ in range(rng.integers(2, 5)):
        kind = rng.integers(3)
        size = rng.uniform(0.015, 0.04)
        part = (_box(*rng.uniform(0.02, 0.06, 3)) if kind == 0 else
                mf.Manifold.sphere(size, SEGMENTS) if kind == 1 else _cyl(size, rng.uniform(0.02, 0.06)))
        part = part.rotate(list(rng.uniform(0, 90, 3))).translate(list(rng.uniform(-0.03, 0.03, 3)))
        parts.append(part)
    out = parts[0]
    for p in parts[1:]:
        out = out + p
    # Keep one connected body: if the union fell apart, join with the hull of the pieces.
    if len(out.decompose()) > 1:
        out = out + mf.Manifold.hull(out).scale([0.5, 0.5, 0.5])
        if len(out.decompose()) > 1:
            out = mf.Manifold.hull(out)
    return out


FAMILIES: dict[str, Callable[[Rng], mf.Manifold]] = {
    "cuboid": cuboid, "plate": plate, "book": book, "cylinder": cylinder, "bottle": bottle,
    "frustum": frustum, "ellipsoid": ellipsoid, "capsule": capsule, "mug": mug, "bowl": bowl,
    "block": block, "wedge": wedge, "convex_hull": convex_hull, "toy": toy,
}
# Families whose members are convex: one hull is exact, CoACD is skipped.
CONVEX_FAMILIES = {"cuboid", "plate", "cylinder", "frustum", "ellipsoid", "capsule", "wedge", "convex_hull"}
# Held-out families: the `unseen` split has shapes the training set has no member of.
UNSEEN_FAMILIES = {"bottle", "wedge"}


def to_trimesh(solid: mf.Manifold) -> trimesh.Trimesh:
    mesh = solid.to_mesh()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts),
                           process=True)


def make_family_mesh(family: str, seed: int) -> trimesh.Trimesh:
    if family not in FAMILIES:
        raise ValueError(f"unknown family {family!r}; known: {sorted(FAMILIES)}")
    solid = FAMILIES[family](np.random.default_rng(seed))
    if solid.is_empty() or solid.status() != mf.Error.NoError:
        raise ValueError(f"family {family} seed {seed}: boolean failed ({solid.status()})")
    return to_trimesh(solid)
