"""One watertight mesh -> one library object: normalised, decomposed, sampled, dropped."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import trimesh

from corn_drake.assets.processing.decompose import DecompositionConfig, decompose, union_volume
from corn_drake.assets.processing.hulls import HullConfig, loadable_hull, obj_text
from corn_drake.assets.ingest import UNIT_SYMBOLS, Rejected
from corn_drake.assets.processing.stable_poses import DropConfig, find_stable_poses
from corn_drake.config.plumbing.bounds import one_of
from corn_drake.storage.atomic_files import save_npy, write_text
from corn_drake.scene.objects import ObjectSpec


@dataclasses.dataclass
class ProcessConfig:
    BOUNDS = {"radius": "range > 0", "keep_size_radius": "range > 0",
              "unit": one_of(("auto", *UNIT_SYMBOLS)), "density": "> 0",
              "cloud_points": "[1, 65536]", "thin_ratio": ">= 1"}

    # Object radius range (m) from the authors' code's domain randomisation (the paper itself
    # gives a 0.1-0.3 m scale); contact data uses its own U(0.04, 0.12) (contact/generate.py).
    radius: tuple[float, float] = (0.05, 0.10)
    # `objects --keep-size`: an ingested mesh keeps its real size (the unit read from the file,
    # ingest.detect_unit) instead of a radius drawn from `radius`, if that size lies in
    # `keep_size_radius` (m, the largest distance from the centre of mass): no smaller than the
    # finger pads are wide (2 cm) and the table's contact resolution (2 cm), no larger than the
    # paper's largest objects (0.3 m across), which already cover most of the 0.4 x 0.5 m table.
    keep_size: bool = False
    keep_size_radius: tuple[float, float] = (0.02, 0.15)
    # `objects --unit`: the unit of the meshes' numbers (m, cm, mm), or "auto": read from each
    # mesh's size (ingest.detect_unit).
    unit: str = "auto"
    density: float = 300.0  # kg/m^3, the authors' DexGraspNet conversion
    cloud_points: int = 2048
    thin_ratio: float = 2.5
    decomposition: DecompositionConfig = dataclasses.field(default_factory=DecompositionConfig)
    hulls: HullConfig = dataclasses.field(default_factory=HullConfig)
    drops: DropConfig = dataclasses.field(default_factory=DropConfig)


def normalise(mesh: trimesh.Trimesh, radius: float) -> trimesh.Trimesh:
    """Centre on the volume centroid and scale so the max vertex distance is `radius`."""
    mesh = mesh.copy()
    mesh.apply_translation(-mesh.center_mass)
    mesh.apply_scale(radius / np.linalg.norm(mesh.vertices, axis=1).max())
    return mesh


def obj_vertices(text: str) -> np.ndarray:
    """The (N, 3) vertices of OBJ text."""
    rows = [line.split()[1:4] for line in text.splitlines() if line.startswith("v ")]
    return np.array(rows, dtype=float).reshape(-1, 3)


def _write_obj(path: Path, mesh: trimesh.Trimesh) -> None:
    write_text(path, obj_text(mesh))


def loadable_hulls(hulls: list[trimesh.Trimesh], cfg: HullConfig
                   ) -> tuple[list[tuple[str, trimesh.Trimesh]], list[str], list[str]]:
    """([(OBJ text, hull)] Drake loads both ways, repair notes, warnings for dropped hulls);
    raises Rejected when no hull is left."""
    kept, repairs, dropped = [], [], []
    for i, hull in enumerate(hulls):
        text, mesh, note = loadable_hull(hull, cfg)
        if text is None:
            dropped.append(f"convex piece {i} {note}")
            continue
        if note:
            repairs.append(f"convex piece {i} {note}")
        kept.append((text, mesh))
    if not kept:
        raise Rejected(f"no convex hull Drake can load ({'; '.join(dropped)})")
    return kept, repairs, dropped


def kept_fraction(drop_stats: dict) -> float:
    """Share of the poses holding in the training setting that hold in the second one too."""
    held = drop_stats["verified"]
    return drop_stats["held_second_setting"] / held if held else 0.0


def process_object(mesh: trimesh.Trimesh, object_id: str, out: Path, rng: np.random.Generator,
                   cfg: ProcessConfig, convex: bool, cache_dir: Path | None) -> dict:
    """Writes the object's files under out/object_id; returns its manifest entry fields, and
    under "timings" its steps' wall times (which the builder keeps out of the manifest)."""
    timings = {}
    t = time.perf_counter()
    target = rng.uniform(*cfg.radius)  # drawn either way: the rest of the stream stays the same
    if cfg.keep_size:  # its own size (ingest checked that it fits keep_size_radius)
        target = float(np.linalg.norm(mesh.vertices - mesh.center_mass, axis=1).max())
    mesh = normalise(mesh, target)
    radius = float(np.linalg.norm(mesh.vertices, axis=1).max())
    if convex:
        hulls, coacd_runs = [mesh.convex_hull], 0
        hull_ratio = union_volume(hulls) / float(mesh.volume)
    else:
        hulls, hull_ratio, coacd_runs = decompose(mesh, cfg.decomposition, cache_dir)
    timings["decompose_s"] = time.perf_counter() - t
    t_check = time.perf_counter()
    checked, repairs, dropped = loadable_hulls(hulls, cfg.hulls)
    hulls = [h for _, h in checked]
    if repairs or dropped:
        hull_ratio = union_volume(hulls) / float(mesh.volume)
    timings["hull_check_s"] = time.perf_counter() - t_check
    t = time.perf_counter()
    points, faces = trimesh.sample.sample_surface(mesh, cfg.cloud_points, seed=int(rng.integers(1 << 31)))
    cloud = np.concatenate([points, mesh.face_normals[faces]], axis=1)
    extents = np.sort(mesh.bounding_box_oriented.primitive.extents)
    mass = float(cfg.density * mesh.volume)
    lo, hi = mesh.bounds
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    folder = out / object_id
    folder.mkdir(parents=True, exist_ok=True)
    hull_paths = []
    for i, (text, _) in enumerate(checked):  # exactly the text Drake was shown
        write_text(folder / f"hull_{i:02d}.obj", text)
        hull_paths.append(folder / f"hull_{i:02d}.obj")
    _write_obj(folder / "visual.obj", mesh)
    save_npy(folder / "cloud.npy", cloud.astype(np.float64))
    spec = ObjectSpec(name=object_id, mass=mass, unit_inertia=mesh.moment_inertia / mesh.mass,
                      com=np.zeros(3), cloud=cloud, stable_poses=np.zeros((0, 7)), radius=radius,
                      bbox_corners=corners, hull_paths=hull_paths)
    t_drop = time.perf_counter()
    # The vertices as written (what Drake and every later reader load), not the in-memory
    # floats they were printed from: the poses are computed from exactly the library's files.
    vertices = np.concatenate([obj_vertices(text) for text, _ in checked])
    poses, drop_stats = find_stable_poses(spec, vertices, rng, cfg.drops)
    timings["stable_poses_s"] = time.perf_counter() - t_drop
    # A wall time, so with the others (the library's build_timings.json), not in the manifest's
    # drop statistics, which are the same on every build.
    timings["second_setting_s"] = drop_stats.pop("second_setting_s")
    save_npy(folder / "stable_poses.npy", poses)
    save_npy(folder / "bbox_corners.npy", corners)
    save_npy(folder / "unit_inertia.npy", np.asarray(mesh.moment_inertia / mesh.mass))
    timings["total_s"] = time.perf_counter() - t
    return {"radius": radius, "mass": mass, "thin": bool(extents[1] >= cfg.thin_ratio * extents[0]),
            "hulls": [f"{object_id}/{p.name}" for p in hull_paths], "visual": f"{object_id}/visual.obj",
            "cloud": f"{object_id}/cloud.npy", "stable_poses": f"{object_id}/stable_poses.npy",
            "bbox_corners": f"{object_id}/bbox_corners.npy",
            "unit_inertia": f"{object_id}/unit_inertia.npy",
            "num_hulls": len(hulls), "hull_repairs": repairs, "warnings": dropped,
            "num_stable_poses": int(len(poses)), "drops": drop_stats,
            "stable_pose_kept_fraction": kept_fraction(drop_stats),
            "hull_volume_ratio": hull_ratio, "coacd_runs": coacd_runs, "timings": timings}
