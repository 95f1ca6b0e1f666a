"""Objects as plain specs (geometry files or primitive sizes, mass, cloud, stable poses).

scene/ never imports assets/: the object library turns its manifest entries into ObjectSpecs,
and this module turns ObjectSpecs into plant bodies.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from corn_drake.contract import TABLE_TOP_Z  # noqa: F401 (re-exported: the scene's readers)
from corn_drake.errors import MissingInputError


@dataclasses.dataclass
class ObjectSpec:
    name: str
    mass: float
    # Rotational inertia about the centre of mass, per unit mass, in the object frame (3x3).
    unit_inertia: np.ndarray
    com: np.ndarray  # centre of mass in the object frame (3,)
    # Surface samples with normals in the object frame, (N, 6): used for the observation cloud.
    cloud: np.ndarray
    # Stable resting poses, (K, 7) xyz + quaternion wxyz of the object frame in the world with the
    # table top at z = 0.4 and the object above (0, 0).
    stable_poses: np.ndarray
    radius: float  # max distance of the surface from the object-frame origin
    # Eight corners of the object-frame bounding box (8, 3): reward keypoints.
    bbox_corners: np.ndarray
    # Exactly one of: convex hull .obj files, or a primitive ("box", size) / ("cylinder", (r, l)).
    hull_paths: list[Path] = dataclasses.field(default_factory=list)
    primitive: tuple[str, tuple[float, ...]] | None = None
    visual_path: Path | None = None
    thin: bool = False

    def __post_init__(self):
        if not self.hull_paths and self.primitive is None:
            raise ValueError(f"object {self.name}: needs hull_paths or a primitive")
        for p in self.hull_paths:
            if not Path(p).is_file():
                raise MissingInputError(f"object {self.name}: mesh file not found: {p}")
        if self.cloud.ndim != 2 or self.cloud.shape[1] != 6 or not np.isfinite(self.cloud).all():
            raise ValueError(f"object {self.name}: cloud must be an (N, 6) array of finite "
                             f"numbers, got shape {self.cloud.shape}"
                             + ("" if np.isfinite(self.cloud).all() else " holding NaN or inf"))
        # Empty is allowed (an object whose stable poses are being computed); envs need K > 0.
        if self.stable_poses.ndim != 2 or self.stable_poses.shape[1] != 7:
            raise ValueError(f"object {self.name}: stable_poses must be (K, 7)")


def _corners(half: np.ndarray) -> np.ndarray:
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    return signs * half


def _wxyz_from_matrix(R: np.ndarray) -> np.ndarray:
    from pydrake.math import RotationMatrix

    q = RotationMatrix(R).ToQuaternion()
    return np.array([q.w(), q.x(), q.y(), q.z()])


def _face_down_poses(half: np.ndarray) -> np.ndarray:
    """Six resting poses of a box (or the 2-3 distinct ones of a cylinder), each face down."""
    rotations = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            # Rotate the face whose outward normal is sign * e_axis onto world -z (face down).
            target = np.array([0.0, 0.0, -1.0])
            src = np.zeros(3)
            src[axis] = sign
            v = np.cross(src, target)
            c = float(src @ target)
            if np.linalg.norm(v) < 1e-12:
                R = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
            else:
                vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
                R = np.eye(3) + vx + vx @ vx / (1 + c)
            rotations.append(R)
    poses = []
    for R in rotations:
        height = np.abs(R @ np.diag(half)).sum(axis=1)[2]  # half extent along world z
        poses.append(np.concatenate([[0.0, 0.0, TABLE_TOP_Z + height], _wxyz_from_matrix(R)]))
    return np.array(poses)


def _sample_box_surface(half: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    areas = np.array([half[1] * half[2], half[0] * half[2], half[0] * half[1]]) * 4
    face_axis = rng.choice(3, size=n, p=areas / areas.sum())
    sign = rng.choice([-1.0, 1.0], size=n)
    pts = rng.uniform(-1, 1, size=(n, 3)) * half
    normals = np.zeros((n, 3))
    pts[np.arange(n), face_axis] = sign * half[face_axis]
    normals[np.arange(n), face_axis] = sign
    return np.concatenate([pts, normals], axis=1)


def box_spec(size, mass: float, cloud_points: int = 2048, seed: int = 0) -> ObjectSpec:
    size = np.asarray(size, float)
    half = size / 2
    unit_inertia = np.diag([size[1] ** 2 + size[2] ** 2, size[0] ** 2 + size[2] ** 2,
                            size[0] ** 2 + size[1] ** 2]) / 12.0
    sorted_ext = np.sort(size)
    return ObjectSpec(
        name=f"box_{size[0]:.3f}x{size[1]:.3f}x{size[2]:.3f}", mass=mass,
        unit_inertia=unit_inertia, com=np.zeros(3),
        cloud=_sample_box_surface(half, cloud_points, np.random.default_rng(seed)),
        stable_poses=_face_down_poses(half), radius=float(np.linalg.norm(half)),
        bbox_corners=_corners(half), primitive=("box", tuple(size)),
        thin=bool(sorted_ext[1] >= 2.5 * sorted_ext[0]))


def cylinder_spec(radius: float, length: float, mass: float, cloud_points: int = 2048,
                  seed: int = 0) -> ObjectSpec:
    rng = np.random.default_rng(seed)
    side_area, cap_area = 2 * np.pi * radius * length, np.pi * radius ** 2
    n_side = int(round(cloud_points * side_area / (side_area + 2 * cap_area)))
    theta = rng.uniform(0, 2 * np.pi, cloud_points)
    pts = np.zeros((cloud_points, 3))
    normals = np.zeros((cloud_points, 3))
    pts[:n_side, 0], pts[:n_side, 1] = radius * np.cos(theta[:n_side]), radius * np.sin(theta[:n_side])
    pts[:n_side, 2] = rng.uniform(-length / 2, length / 2, n_side)
    normals[:n_side, :2] = pts[:n_side, :2] / radius
    r = radius * np.sqrt(rng.uniform(0, 1, cloud_points - n_side))
    cap_sign = rng.choice([-1.0, 1.0], cloud_points - n_side)
    pts[n_side:, 0], pts[n_side:, 1] = r * np.cos(theta[n_side:]), r * np.sin(theta[n_side:])
    pts[n_side:, 2] = cap_sign * length / 2
    normals[n_side:, 2] = cap_sign
    half = np.array([radius, radius, length / 2])
    poses = _face_down_poses(half)[[4, 5]]  # resting on either cap (z axis vertical)
    unit_inertia = np.diag([(3 * radius ** 2 + length ** 2) / 12] * 2 + [radius ** 2 / 2])
    return ObjectSpec(
        name=f"cylinder_r{radius:.3f}_l{length:.3f}", mass=mass, unit_inertia=unit_inertia,
        com=np.zeros(3), cloud=np.concatenate([pts, normals], 1), stable_poses=poses,
        radius=float(np.hypot(radius, length / 2)), bbox_corners=_corners(half),
        primitive=("cylinder", (radius, length)))
