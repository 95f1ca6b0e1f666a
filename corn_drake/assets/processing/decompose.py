"""Convex decomposition with CoACD, cached by mesh hash (re-runs of a library are free)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np
import trimesh

from corn_drake.storage.atomic_files import save_npz


@dataclasses.dataclass
class DecompositionConfig:
    # CoACD's own ranges: a concavity threshold in (0, 1], at least one hull and one search step,
    # preprocess "off" / "on" / "auto".
    BOUNDS = {"threshold": "(0, 1]", "max_convex_hull": "[1, 1024]", "mcts_iterations": ">= 1",
              "mcts_max_depth": ">= 1", "mcts_nodes": ">= 1", "resolution": ">= 1",
              "preprocess_mode": "one of off|on|auto", "seed": "seed", "max_union_ratio": ">= 1",
              "retry_threshold": "(0, 1]", "retry_mcts_iterations": ">= 1",
              "retry_mcts_max_depth": ">= 1"}

    # The authors: threshold 0.05, <= 16 hulls. Fast MCTS settings measured here keep one mesh to
    # a few seconds; preprocessing off because every mesh reaching here is already watertight.
    threshold: float = 0.05
    max_convex_hull: int = 16
    mcts_iterations: int = 60
    mcts_max_depth: int = 2
    mcts_nodes: int = 20
    resolution: int = 1000
    preprocess_mode: str = "off"
    seed: int = 0
    # A union of hulls more than this above the mesh volume gets one more CoACD run with a finer
    # concavity threshold and a deeper search; the tighter of the two decompositions is kept.
    max_union_ratio: float = 1.15
    retry_threshold: float = 0.02
    retry_mcts_iterations: int = 150
    retry_mcts_max_depth: int = 3


def mesh_key(mesh: trimesh.Trimesh, cfg: DecompositionConfig) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(mesh.vertices, np.float64).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, np.int64).tobytes())
    h.update(json.dumps(dataclasses.asdict(cfg), sort_keys=True).encode())
    return h.hexdigest()[:32]


def union_volume(hulls: list[trimesh.Trimesh]) -> float:
    """Volume of the union of the hulls (they overlap, so the sum of their volumes over-counts)."""
    import manifold3d as mf

    total = None
    for h in hulls:
        m = mf.Manifold(mf.Mesh(vert_properties=np.asarray(h.vertices, np.float32),
                                tri_verts=np.asarray(h.faces, np.uint32)))
        total = m if total is None else total + m
    return float(total.volume())


def decompose(mesh: trimesh.Trimesh, cfg: DecompositionConfig,
              cache_dir: Path | None) -> tuple[list[trimesh.Trimesh], float, int]:
    """(hulls, union volume / mesh volume, CoACD runs made) for a watertight concave mesh."""
    volume = float(mesh.volume)
    hulls = convex_decomposition(mesh, cfg, cache_dir)
    ratio = union_volume(hulls) / volume
    if ratio <= cfg.max_union_ratio:
        return hulls, ratio, 1
    finer = dataclasses.replace(cfg, threshold=cfg.retry_threshold,
                                mcts_iterations=cfg.retry_mcts_iterations,
                                mcts_max_depth=cfg.retry_mcts_max_depth)
    retry = convex_decomposition(mesh, finer, cache_dir)
    retry_ratio = union_volume(retry) / volume
    if abs(retry_ratio - 1.0) < abs(ratio - 1.0):
        return retry, retry_ratio, 2
    return hulls, ratio, 2


def convex_decomposition(mesh: trimesh.Trimesh, cfg: DecompositionConfig,
                         cache_dir: Path | None) -> list[trimesh.Trimesh]:
    cache = cache_dir / f"{mesh_key(mesh, cfg)}.npz" if cache_dir else None
    if cache is not None and cache.is_file():
        data = np.load(cache)
        return [trimesh.Trimesh(data[f"v{i}"], data[f"f{i}"]) for i in range(int(data["n"]))]
    import coacd

    coacd.set_log_level("error")
    parts = coacd.run_coacd(
        coacd.Mesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)), threshold=cfg.threshold,
        max_convex_hull=cfg.max_convex_hull, preprocess_mode=cfg.preprocess_mode,
        resolution=cfg.resolution, mcts_nodes=cfg.mcts_nodes, mcts_iterations=cfg.mcts_iterations,
        mcts_max_depth=cfg.mcts_max_depth, seed=cfg.seed)
    hulls = [trimesh.Trimesh(v, f).convex_hull for v, f in parts]
    if cache is not None:
        arrays = {"n": np.array(len(hulls))}
        for i, h in enumerate(hulls):
            arrays[f"v{i}"], arrays[f"f{i}"] = h.vertices, h.faces
        save_npz(cache, **arrays)
    return hulls
