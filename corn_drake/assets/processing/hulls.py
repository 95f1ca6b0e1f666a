"""Convex hull files that Drake loads as rigid and as compliant hydroelastic geometry.

Drake rebuilds a `Convex` from the file's vertices (its own qhull run) and meshes it: a surface
mesh for rigid hydroelastic contact, a fan of tetrahedra from the centroid to every face for
compliant contact. Clusters of nearly coincident vertices, or a vertex nearly on the segment
between two others, give faces of almost no area. Drake then refuses the hull at registration
("A mesh field element was degenerate") or, worse, accepts it and throws in the middle of a
simulation when that face touches something: its `Plane` refuses a face normal (an unnormalised
edge cross product) shorter than 1e-10 ("Cannot instantiate plane from normal ..."; measured:
hulls that registered fine threw this when dropped on a table).

So every hull is checked in Drake before it is written: registered both ways, and every face of
both of Drake's meshes must have an edge cross product FACE_MARGIN times Drake's limit. A hull
that fails is repaired at growing tolerances (merge vertices closer than the tolerance, drop a
vertex within the tolerance of the segment between two of its neighbours: either moves the surface
by at most the tolerance) and checked again; one that no tolerance repairs is dropped.
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

DRAKE_PLANE_MIN_NORMAL = 1e-10  # Drake's Plane: |n| below this throws (geometry/proximity/plane)


@dataclasses.dataclass
class HullConfig:
    BOUNDS = {"tolerances": "vector > 0", "face_margin": ">= 1", "compliant_modulus": "> 0",
              "resolution_hint": "> 0"}

    # Repair tolerances (m), tried in order until Drake accepts the hull. The objects are 5-10 cm
    # across, so even the last one moves the contact surface by a small fraction of a millimetre.
    tolerances: tuple[float, ...] = (1e-5, 1e-4, 3e-4)
    # Faces must clear Drake's limit by this factor: a cross product scales with the square of the
    # object scale, so 100 keeps a hull loadable when scaled down 10x (randomised scale is >= 0.5x).
    face_margin: float = 100.0
    compliant_modulus: float = 1e5  # any positive value: the check is about the mesh, not stiffness
    resolution_hint: float = 0.01


def obj_text(mesh: trimesh.Trimesh) -> str:
    """The OBJ text the library writes for a hull (what Drake reads back)."""
    return trimesh.exchange.obj.export_obj(mesh, include_normals=False, include_texture=False)


def _min_cross(points: np.ndarray, faces: np.ndarray) -> float:
    """Smallest |(b - a) x (c - a)| over the triangles `faces` index into `points`."""
    a, b, c = (points[faces[:, k]] for k in range(3))
    return float(np.linalg.norm(np.cross(b - a, c - a), axis=1).min())


def _drake_face_cross(mesh) -> float:
    """Smallest edge cross product over the faces of a Drake VolumeMesh or TriangleSurfaceMesh."""
    points = np.array([mesh.vertex(i) for i in range(mesh.num_vertices())])
    if hasattr(mesh, "tetrahedra"):
        tets = np.array([[t.vertex(k) for k in range(4)] for t in mesh.tetrahedra()])
        faces = np.concatenate([tets[:, f] for f in ([0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3])])
    else:
        faces = np.array([[t.vertex(k) for k in range(3)] for t in mesh.triangles()])
    return _min_cross(points, faces)


def drake_hull_problem(path: Path, cfg: HullConfig = HullConfig()) -> str | None:
    """None if Drake loads the OBJ at `path` as a rigid and as a compliant hydroelastic Convex
    with every face of both meshes above its plane limit (times the margin); else the reason."""
    from pydrake.geometry import (AddCompliantHydroelasticProperties,
                                  AddRigidHydroelasticProperties, Convex, ProximityProperties)
    from pydrake.math import RigidTransform
    from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
    from pydrake.multibody.tree import SpatialInertia
    from pydrake.systems.framework import DiagramBuilder

    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.001)
    body = plant.AddRigidBody("hull", SpatialInertia.SolidSphereWithMass(0.1, 0.05))
    rigid, compliant = ProximityProperties(), ProximityProperties()
    AddRigidHydroelasticProperties(cfg.resolution_hint, rigid)
    AddCompliantHydroelasticProperties(cfg.resolution_hint, cfg.compliant_modulus, compliant)
    limit = DRAKE_PLANE_MIN_NORMAL * cfg.face_margin
    for name, props in (("rigid", rigid), ("compliant", compliant)):
        try:
            gid = plant.RegisterCollisionGeometry(body, RigidTransform(), Convex(str(path)), name,
                                                  props)
        except RuntimeError as e:
            return f"Drake refuses it as {name} hydroelastic geometry: {e}"
        smallest = _drake_face_cross(scene_graph.model_inspector().maybe_get_hydroelastic_mesh(gid))
        if smallest < limit:
            return (f"its {name} hydroelastic mesh has a degenerate face (edge cross product "
                    f"{smallest:.3g} < {limit:.3g})")
    plant.Finalize()
    builder.Build().CreateDefaultContext()
    return None


def _merge_close(points: np.ndarray, tol: float) -> np.ndarray:
    """Each cluster of points linked by distances < tol becomes its mean."""
    pairs = cKDTree(points).query_pairs(tol, output_type="ndarray")
    n = len(points)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    count, label = connected_components(graph, directed=False)
    sums = np.zeros((count, 3))
    np.add.at(sums, label, points)
    return sums / np.bincount(label, minlength=count)[:, None]


def _distance_to_segments(p: np.ndarray, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Distances from point p to the segments u[i]-w[i]."""
    d = w - u
    along = np.einsum("ij,ij->i", p - u, d) / np.einsum("ij,ij->i", d, d).clip(min=1e-300)
    t = np.clip(along, 0, 1)
    return np.linalg.norm(p - (u + t[:, None] * d), axis=1)


def _redundant_vertices(hull: trimesh.Trimesh, tol: float) -> list[int]:
    """Hull vertices within `tol` of the segment between two of their hull neighbours.

    Such a vertex makes a face of almost no area wherever a triangulation puts it in one triangle
    with those neighbours (Drake triangulates the merged polygons of its own hull, so the faces it
    makes need not be the faces of `hull`). The hull without it is within `tol` of the hull with
    it; no two neighbours are returned, so dropping them all keeps that bound.
    """
    scored = []
    for v, nbrs in enumerate(hull.vertex_neighbors):
        if len(nbrs) < 2:
            continue
        i, j = np.triu_indices(len(nbrs), 1)
        pts = hull.vertices[nbrs]
        nearest = _distance_to_segments(hull.vertices[v], pts[i], pts[j]).min()
        if nearest < tol:
            scored.append((nearest, v))
    dropped: set[int] = set()
    for _, v in sorted(scored):
        if dropped.isdisjoint(hull.vertex_neighbors[v]):
            dropped.add(v)
    return sorted(dropped)


def repair_hull(vertices: np.ndarray, tol: float) -> trimesh.Trimesh | None:
    """The convex hull of `vertices` with near-duplicates merged and vertices nearly on the segment
    between two neighbours dropped, or None when less than a solid is left (a hull thinner than
    about `tol`)."""
    points = _merge_close(np.asarray(vertices, float), tol)
    for _ in range(len(points)):
        if len(points) < 4:
            return None
        try:
            hull = trimesh.convex.convex_hull(points)
        except Exception:  # qhull: the points are (nearly) flat
            return None
        redundant = _redundant_vertices(hull, tol)
        if not redundant:
            return hull if hull.volume > 0 else None
        points = np.delete(hull.vertices, redundant, axis=0)
    return None


def _checked_text(mesh: trimesh.Trimesh, cfg: HullConfig) -> tuple[str, str | None]:
    """(OBJ text, Drake's problem with exactly that text or None)."""
    text = obj_text(mesh)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "hull.obj"  # Drake's Convex needs the .obj suffix
        path.write_text(text)
        return text, drake_hull_problem(path, cfg)


def loadable_hull(hull: trimesh.Trimesh, cfg: HullConfig = HullConfig()
                  ) -> tuple[str | None, trimesh.Trimesh | None, str | None]:
    """(OBJ text Drake accepts, the hull it describes, a note on what was done) for one hull.
    The text is None when no repair tolerance gives a hull Drake accepts; the note then says why.
    """
    text, problem = _checked_text(hull, cfg)
    if problem is None:
        return text, hull, None
    for tol in cfg.tolerances:
        repaired = repair_hull(hull.vertices, tol)
        if repaired is None:
            break  # a larger tolerance only removes more
        text, later = _checked_text(repaired, cfg)
        if later is None:
            return text, repaired, f"repaired at {tol:g} m ({problem})"
    return None, None, f"dropped: {problem}"
