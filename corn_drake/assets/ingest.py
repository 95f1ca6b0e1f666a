"""Turning user mesh files into watertight single-body meshes, or a clear rejection reason.

Accepted: OBJ, STL, PLY, GLB/GLTF, OFF (trimesh loaders). Scenes are merged; NaN/inf vertices,
empty files, garbage bytes, degenerate-only meshes and unsupported extensions are rejected with a
reason; several disconnected bodies keep the largest (with a warning); an open mesh is repaired
by trimesh, and if it stays open, replaced by its convex hull with a recorded warning.

A mesh file carries no unit (glTF's is metres by its specification): `detect_unit` reads one
from the mesh's size, the first of metres, millimetres and centimetres that makes it a tabletop
object (1 cm to 1 m across). The library then rescales every mesh to its radius range, or with
`objects --keep-size` keeps its size in that unit where it fits (process.ProcessConfig).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

SUPPORTED = {".obj", ".stl", ".ply", ".glb", ".gltf", ".off"}


class Rejected(Exception):
    """The input cannot become an object; the message is the manifest's reason."""


def find_mesh_files(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob("*") if p.is_file())


def load_watertight(path: Path) -> tuple[trimesh.Trimesh, list[str]]:
    """(mesh, warnings) or raise Rejected(reason)."""
    warnings: list[str] = []
    if path.suffix.lower() not in SUPPORTED:
        raise Rejected(f"unsupported extension {path.suffix!r} (supported: {sorted(SUPPORTED)})")
    if path.stat().st_size == 0:
        raise Rejected("empty file")
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as e:  # trimesh raises many types on garbage input
        raise Rejected(f"unreadable mesh ({type(e).__name__}: {e})") from e
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise Rejected("no triangles in the file")
    vertices = np.asarray(loaded.vertices, float)
    if not np.isfinite(vertices).all():
        raise Rejected("non-finite (NaN/inf) vertex coordinates")
    mesh = trimesh.Trimesh(vertices, loaded.faces, process=True)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    if len(mesh.faces) < 4:
        raise Rejected(f"only {len(mesh.faces)} non-degenerate triangles: not a solid")
    bodies = mesh.split(only_watertight=False)
    if len(bodies) > 1:
        bodies = sorted(bodies, key=lambda b: b.area, reverse=True)
        warnings.append(f"{len(bodies)} separate bodies: kept the largest")
        mesh = bodies[0]
    if not mesh.is_watertight:
        trimesh.repair.fill_holes(mesh)
        trimesh.repair.fix_normals(mesh)
    if not mesh.is_watertight:
        mesh = mesh.convex_hull
        warnings.append("not watertight after repair: replaced by its convex hull")
    if mesh.volume <= 0 or not np.isfinite(mesh.volume):
        raise Rejected("zero or undefined volume")
    if mesh.volume < 0:
        mesh.invert()
    return mesh, warnings


# Sizes across (m) a tabletop object has: the test of a unit read from a mesh's size.
TABLETOP_ACROSS = (0.01, 1.0)
# The units tried, in order (metres first: a mesh that reads as a tabletop object in metres is
# taken so; millimetres before centimetres, CAD's and STL's usual unit).
UNITS = (("metres", 1.0), ("millimetres", 1e-3), ("centimetres", 1e-2))


# `objects --unit`: the unit a user says its files are in, by its symbol.
UNIT_SYMBOLS = {"m": "metres", "cm": "centimetres", "mm": "millimetres"}


def detect_unit(size: float, suffix: str, given: str = "auto") -> tuple[str, float, str]:
    """(unit, metres per unit, how it was found) of a mesh whose largest extent is `size` in the
    file's numbers: the unit `given` by its symbol (UNIT_SYMBOLS), else a file type's own unit
    (glTF: metres), else the first of UNITS that makes it a tabletop size. Why a user may say
    it: a size fits more than one unit (a 40 cm box written as 40 reads as 4 cm in mm)."""
    if given != "auto":
        unit = UNIT_SYMBOLS[given]
        return unit, dict(UNITS)[unit], "given by --unit"
    if suffix.lower() in (".glb", ".gltf"):
        return "metres", 1.0, "glTF's unit"
    lo, hi = TABLETOP_ACROSS
    for unit, metres in UNITS:
        if lo <= size * metres <= hi:
            return unit, metres, "from its size"
    return "metres", 1.0, f"no unit makes {size:.4g} a tabletop size (1 cm to 1 m)"
