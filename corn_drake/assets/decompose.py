"""Convex decomposition with CoACD, cached by mesh hash (re-runs of a library are free)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np
import trimesh

from corn_drake.io_utils import save_npz


@dataclasses.dataclass
class DecompositionConfig:
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


def mesh_key(mesh: trimesh.Trimesh, cfg: DecompositionConfig) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(mesh.vertices, np.float64).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, np.int64).tobytes())
    h.update(json.dumps(dataclasses.asdict(cfg), sort_keys=True).encode())
    return h.hexdigest()[:32]


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
