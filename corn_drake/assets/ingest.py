"""Turning user mesh files into watertight single-body meshes, or a clear rejection reason.

Accepted: OBJ, STL, PLY, GLB/GLTF, OFF (trimesh loaders). Scenes are merged; NaN/inf vertices,
empty files, garbage bytes, degenerate-only meshes and unsupported extensions are rejected with a
reason; several disconnected bodies keep the largest (with a warning); an open mesh is repaired
by trimesh, and if it stays open, replaced by its convex hull with a recorded warning. Scale is
normalised later, so a mesh in millimetres (or 1e4x too large) only gets a warning.
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
    size = float(np.ptp(mesh.vertices, axis=0).max())
    if size > 2.0 or size < 0.005:
        warnings.append(f"size {size:.4g} (units?): rescaled to the library's radius range")
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
