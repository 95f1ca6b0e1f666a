"""Contact-pretraining data (the paper's Algorithm 1), vectorised over samples in numpy.

Per sample: an object scaled to radius U(0.04, 0.12) m; hand (panda_tool) and object poses
uniform in x +-0.24, y +-0.30, z [0.35, 0.65] with uniform rotations; the object point nearest to
the gripper (exact box-union signed distance d, unit gradient u in the world) sets the
displacement: the object moves by -(d + 0.05 N(0,1) + 0.03) u, so its nearest point ends near
signed distance -(0.03 + 0.05 N): about 70 % of samples penetrate (measured; the offset is
there to raise the share of patches in contact), the rest are near misses. Then 512 of the
object's surface samples are kept and labelled inside/outside the gripper.

Shards are independent: shard i of a split draws from a generator seeded by (seed, split, i),
so a killed run resumes by skipping finished shards and the same seed gives the same bytes.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from corn_drake.config.plumbing.bounds import relation
from corn_drake.contact.gripper_sdf import GripperSDF
from corn_drake.assets.library_clouds import ObjectCloud
from corn_drake.transforms import quat_wxyz_to_matrix

SPLIT_CODES = {"train": 0, "val": 1, "unseen": 2}


@dataclasses.dataclass
class ContactDataConfig:
    # The object's placements: a box [low, high] the object's centre is drawn in, above the
    # gripper's reach of the table (contact/generate.py's samples).
    BOUNDS = {"points": "[1, 65536]", "radius": "range > 0", "low": "vector 3 finite",
              "high": "vector 3 finite", "noise": ">= 0", "offset": ">= 0"}
    RELATIONS = (relation("low", "<= {high} in every coordinate",
                          lambda low, high: all(a <= b for a, b in zip(low, high)), "high"),)

    points: int = 512
    radius: tuple[float, float] = (0.04, 0.12)
    low: tuple[float, float, float] = (-0.24, -0.30, 0.35)
    high: tuple[float, float, float] = (0.24, 0.30, 0.65)
    noise: float = 0.05
    offset: float = 0.03


def random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniform rotations (n, 3, 3) from normalised Gaussian quaternions; also returns wxyz."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return quat_wxyz_to_matrix(q), q


def shard_rng(seed: int, split: str, shard: int) -> np.random.Generator:
    return np.random.default_rng([seed, SPLIT_CODES[split], shard])


def generate_samples(objects: list[ObjectCloud], n: int, rng: np.random.Generator,
                     sdf: GripperSDF, cfg: ContactDataConfig = ContactDataConfig()) -> dict:
    """n samples as the arrays of one shard."""
    lo, hi = np.array(cfg.low), np.array(cfg.high)
    which = rng.integers(len(objects), size=n)
    radius = rng.uniform(*cfg.radius, size=n)
    scale = radius / np.array([objects[i].radius for i in which])
    # Library clouds are random surface samples: any prefix of equal length is a fair sample.
    m = min(len(o.points) for o in objects)
    table = np.stack([o.points[:m] for o in objects]).astype(np.float32)
    local = table[which] * scale[:, None, None].astype(np.float32)  # (n, m, 3)
    R_h, q_h = random_rotations(rng, n)
    R_o, q_o = random_rotations(rng, n)
    p_h, p_o = rng.uniform(lo, hi, (n, 3)), rng.uniform(lo, hi, (n, 3))
    # Object -> tool: R = R_h^T R_o, p = R_h^T (p_o - p_h). Nearest point over all m samples.
    R_to = np.einsum("nji,njk->nik", R_h, R_o)
    p_to = np.einsum("nji,nj->ni", R_h, p_o - p_h)
    nearest = sdf.nearest_in_batch(local, R_to, p_to)
    nearest_local = local[np.arange(n), nearest].astype(np.float64)
    d_min, grad = sdf.signed_distance(np.einsum("nij,nj->ni", R_to, nearest_local) + p_to)
    u = np.einsum("nij,nj->ni", R_h, grad)  # tool -> world
    shift = -(d_min + cfg.noise * rng.normal(size=n) + cfg.offset)[:, None] * u
    p_o = p_o + shift
    p_to = np.einsum("nji,nj->ni", R_h, p_o - p_h)
    keep = np.argpartition(rng.random((n, m)), cfg.points, axis=1)[:, :cfg.points]
    kept = np.take_along_axis(local, keep[..., None], 1)
    labels = sdf.inside_batch(kept, R_to, p_to)
    points = torch.baddbmm(torch.from_numpy(p_o.astype(np.float32)).unsqueeze(1), torch.from_numpy(kept),
                           torch.from_numpy(R_o.astype(np.float32)).transpose(1, 2)).numpy()
    ids = np.array([objects[i].id for i in which])
    return {"points": points.astype(np.float32), "labels": labels,
            "hand_pose": np.concatenate([p_h, q_h], 1), "object_pose": np.concatenate([p_o, q_o], 1),
            "object_id": ids, "scale": scale}
