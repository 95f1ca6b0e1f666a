"""ObjectSegmentation: merged camera clouds -> the object's points, as on the real robot.

Geometric mode (the paper's real-world chain), in order:
  1. drop pixels with no return (non-finite);
  2. crop to the workspace box above the table;
  3. drop points within `table_margin` of the table top;
  4. drop points inside the robot's link primitives (boxes / cylinders, grown by
     `robot_margin`), posed by forward kinematics of the robot state input;
  5. for dense images (D435-like), voxel thinning to `max_px_per_m`; then radius outlier
     removal (n neighbours within r; outlier_points gives n for the rig's pixel density);
  6. DBSCAN (dbscan_eps gives eps for that density); the largest cluster is the object.
Ground-truth mode keeps the pixels whose render label is the object's body (training only).

Outputs: ``object_cloud`` (PointCloud of every kept point, for the tracker), ``points``
(num_points x 3 flattened, resampled), ``num_points`` (1: kept points before resampling; 0
means nothing was seen and ``points`` is all zeros).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Box, Cylinder, Sphere
from pydrake.math import RigidTransform
from pydrake.perception import BaseField, Fields, PointCloud
from pydrake.systems.framework import LeafSystem
from pydrake.systems.sensors import ImageLabel16I

from corn_drake.contract import NUM_JOINTS, ROBOT_STATE_DIM
from corn_drake.errors import InputError
from corn_drake.scene.franka import make_controller_plant


@dataclasses.dataclass(frozen=True)
class LinkPrimitive:
    body_name: str
    kind: str  # "box" | "cylinder" | "sphere"
    size: np.ndarray  # box: half extents (3); cylinder: (radius, half length); sphere: (radius,)
    X_BG: np.ndarray  # (4, 4) pose of the shape in its body frame


def robot_link_primitives(plant, scene_graph, model_instance) -> list[LinkPrimitive]:
    """The robot's visual shapes (what the cameras see) as primitives in their body frames."""
    inspector = scene_graph.model_inspector()
    prims = []
    for bi in plant.GetBodyIndices(model_instance):
        body = plant.get_body(bi)
        for gid in plant.GetVisualGeometriesForBody(body):
            shape = inspector.GetShape(gid)
            X = inspector.GetPoseInFrame(gid).GetAsMatrix4()
            if isinstance(shape, Box):
                prims.append(LinkPrimitive(body.name(), "box", np.array(
                    [shape.width(), shape.depth(), shape.height()]) / 2, X))
            elif isinstance(shape, Cylinder):
                prims.append(LinkPrimitive(body.name(), "cylinder",
                                           np.array([shape.radius(), shape.length() / 2]), X))
            elif isinstance(shape, Sphere):
                prims.append(LinkPrimitive(body.name(), "sphere", np.array([shape.radius()]), X))
            else:
                raise ValueError(f"robot visual {inspector.GetName(gid)} is a "
                                 f"{type(shape).__name__}; segmentation needs box/cylinder/sphere")
    return prims


def inside_primitives(points: np.ndarray, prims, poses, margin: float) -> np.ndarray:
    """Mask of points (N, 3) inside any primitive grown by `margin`; poses: X_WG (4x4) each."""
    inside = np.zeros(len(points), bool)
    for prim, X in zip(prims, poses):
        local = (points - X[:3, 3]) @ X[:3, :3]  # R^T (p - t), row-wise
        if prim.kind == "box":
            inside |= (np.abs(local) <= prim.size + margin).all(axis=1)
        elif prim.kind == "cylinder":
            r, h = prim.size
            inside |= ((local[:, 0] ** 2 + local[:, 1] ** 2 <= (r + margin) ** 2)
                       & (np.abs(local[:, 2]) <= h + margin))
        else:
            inside |= (local ** 2).sum(axis=1) <= (prim.size[0] + margin) ** 2
    return inside


class RobotLinkPoser:
    """Forward kinematics of the robot's link primitives from joint angles (robot-only plant)."""

    def __init__(self, prims, robot_base):
        self.prims = prims
        self._plant = make_controller_plant()
        self._context = self._plant.CreateDefaultContext()
        self._X_W0 = RigidTransform(np.asarray(robot_base, float)).GetAsMatrix4()
        self._bodies = [self._plant.GetBodyByName(p.body_name) for p in prims]

    def poses(self, q: np.ndarray) -> list[np.ndarray]:
        self._plant.SetPositions(self._context, q)
        out, cache = [], {}
        for body, prim in zip(self._bodies, self.prims):
            if body.index() not in cache:
                cache[body.index()] = self._X_W0 @ self._plant.EvalBodyPoseInWorld(
                    self._context, body).GetAsMatrix4()
            out.append(cache[body.index()] @ prim.X_BG)
        return out


def outlier_points(cfg, px_per_m: float) -> int:
    """Radius-outlier neighbour count n for images of `px_per_m` (SegmentationConfig explains
    outlier_scaling): the paper's count scaled by the ratio of points per surface patch."""
    if cfg.outlier_scaling == "none":
        return cfg.outlier_neighbours
    if cfg.outlier_scaling != "pixel_density":
        raise InputError(f"segmentation.outlier_scaling must be pixel_density or none, "
                         f"got {cfg.outlier_scaling!r}")
    scale = (px_per_m / cfg.outlier_reference_px_per_m) ** 2
    return max(2, int(round(cfg.outlier_neighbours * scale)))


def dbscan_eps(cfg, px_per_m: float) -> float:
    """DBSCAN eps: cfg.dbscan_eps, grown to dbscan_min_eps_pixels pixel footprints."""
    return max(cfg.dbscan_eps, cfg.dbscan_min_eps_pixels / px_per_m)


@dataclasses.dataclass
class SegmentationStats:
    """How many points each stage kept (for tests, the bench and debugging)."""
    finite: int = 0
    cropped: int = 0
    above_table: int = 0
    not_robot: int = 0
    inliers: int = 0
    cluster: int = 0


def voxel_subsample(points: np.ndarray, voxel: float) -> np.ndarray:
    """Indices of one point per occupied voxel (the first in order), so indices stay original."""
    keys = np.floor(points / voxel).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    return np.sort(first)


def segment_geometric(points: np.ndarray, link_poses, prims, cfg, table_box, outlier_n: int,
                      eps: float, stats: SegmentationStats | None = None,
                      voxel: float = 0.0) -> np.ndarray:
    """Indices into `points` (N, 3; may hold non-finite rows) of the object's points.

    table_box: (x_half, y_half, top_z) of the table centred at the world origin.
    """
    import open3d as o3d

    stats = stats if stats is not None else SegmentationStats()
    idx = np.flatnonzero(np.isfinite(points).all(axis=1))
    stats.finite = len(idx)
    p = points[idx]
    xh, yh, top = table_box
    m = cfg.crop_margin_xy
    keep = ((np.abs(p[:, 0]) <= xh + m) & (np.abs(p[:, 1]) <= yh + m)
            & (p[:, 2] <= top + cfg.crop_height))
    stats.cropped = int(keep.sum())
    keep &= p[:, 2] > top + cfg.table_margin
    stats.above_table = int(keep.sum())
    idx, p = idx[keep], p[keep]
    if len(p) and prims:
        keep = ~inside_primitives(p, prims, link_poses, cfg.robot_margin)
        idx, p = idx[keep], p[keep]
    stats.not_robot = len(idx)
    if len(p) == 0:
        return idx
    if voxel > 0:
        # Dense images (a D435's 640 x 480): thin to the density n and eps were scaled for;
        # radius search and DBSCAN cost grows with the square of the density.
        keep = voxel_subsample(p, voxel)
        idx, p = idx[keep], p[keep]
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    if outlier_n > 1:
        _, inl = pcd.remove_radius_outlier(nb_points=outlier_n, radius=cfg.outlier_radius)
        inl = np.asarray(inl, int)
        idx, p = idx[inl], p[inl]
        pcd = pcd.select_by_index(inl)
    stats.inliers = len(idx)
    if len(p) < cfg.dbscan_min_points:
        stats.cluster = 0
        return idx[:0]
    labels = np.asarray(pcd.cluster_dbscan(eps=eps, min_points=cfg.dbscan_min_points))
    valid = labels >= 0
    if not valid.any():
        stats.cluster = 0
        return idx[:0]
    best = np.bincount(labels[valid]).argmax()
    idx = idx[labels == best]
    stats.cluster = len(idx)
    return idx


def resample(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Exactly n rows: a random subset, or every row plus random repeats when there are fewer."""
    if len(points) == 0:
        return np.zeros((n, 3))
    if len(points) >= n:
        return points[rng.choice(len(points), n, replace=False)]
    extra = rng.choice(len(points), n - len(points), replace=True)
    return np.concatenate([points, points[extra]])


def _to_point_cloud(p: np.ndarray) -> PointCloud:
    pc = PointCloud(len(p), Fields(BaseField.kXYZs))
    if len(p):
        pc.mutable_xyzs()[:] = p.T
    return pc


class ObjectSegmentation(LeafSystem):
    """Inputs ``cloud{i}`` (PointCloud, world frame, one per camera), ``label{i}``
    (ImageLabel16I; ground-truth mode), ``robot_state`` (joint positions and velocities;
    geometric mode). `px_per_m`: the images' rows per metre at the eye distance
    (CameraRig.px_per_m), which sets the outlier count and DBSCAN eps."""

    def __init__(self, cfg, num_cameras: int, *, table_size, px_per_m: float, robot_base=None,
                 prims=None, object_label: int | None = None):
        super().__init__()
        if cfg.mode not in ("geometric", "ground_truth"):
            raise InputError(f"segmentation.mode must be geometric or ground_truth, got {cfg.mode!r}")
        if cfg.mode == "ground_truth" and object_label is None:
            raise ValueError("ground_truth segmentation needs the object's render label")
        self.cfg = cfg
        self._n_cam = num_cameras
        table_size = np.asarray(table_size, float)
        from corn_drake.scene.objects import TABLE_TOP_Z
        self._table_box = (table_size[0] / 2, table_size[1] / 2, TABLE_TOP_Z)
        self._label = object_label
        self._poser = RobotLinkPoser(prims, robot_base) if prims else None
        density = min(px_per_m, cfg.max_px_per_m)
        self.voxel = 1.0 / cfg.max_px_per_m if px_per_m > cfg.max_px_per_m else 0.0
        self.outlier_n = outlier_points(cfg, density)
        self.eps = dbscan_eps(cfg, density)
        for i in range(num_cameras):
            self.DeclareAbstractInputPort(f"cloud{i}", AbstractValue.Make(PointCloud()))
        if cfg.mode == "ground_truth":
            for i in range(num_cameras):
                self.DeclareAbstractInputPort(f"label{i}", AbstractValue.Make(ImageLabel16I()))
        self.DeclareVectorInputPort("robot_state", ROBOT_STATE_DIM)
        self._cloud_port = self.DeclareAbstractOutputPort(
            "object_cloud", lambda: AbstractValue.Make(PointCloud()), self._calc_cloud)
        self.DeclareVectorOutputPort("points", 3 * cfg.num_points, self._calc_points)
        self.DeclareVectorOutputPort("num_points", 1, self._calc_count)

    def merged_points(self, context) -> np.ndarray:
        return np.concatenate([self.GetInputPort(f"cloud{i}").Eval(context).xyzs().T
                               for i in range(self._n_cam)])

    def merged_labels(self, context) -> np.ndarray:
        return np.concatenate([self.GetInputPort(f"label{i}").Eval(context).data.reshape(-1)
                               for i in range(self._n_cam)])

    def segment_indices(self, context, stats: SegmentationStats | None = None) -> np.ndarray:
        """Indices into merged_points(context) of the object's points."""
        pts = self.merged_points(context)
        if self.cfg.mode == "ground_truth":
            keep = (self.merged_labels(context) == self._label) & np.isfinite(pts).all(axis=1)
            return np.flatnonzero(keep)
        q = self.GetInputPort("robot_state").Eval(context)[:NUM_JOINTS]
        if self._poser is not None and np.isfinite(q).all():
            prims, poses = self._poser.prims, self._poser.poses(q)
        else:
            prims, poses = [], []
        return segment_geometric(pts, poses, prims, self.cfg, self._table_box, self.outlier_n,
                                 self.eps, stats, self.voxel)

    def segment(self, context) -> np.ndarray:
        """The object's points (K, 3) in the world frame."""
        return self.merged_points(context)[self.segment_indices(context)]

    def _calc_cloud(self, context, output):
        output.set_value(_to_point_cloud(self.segment(context)))

    def _kept(self, context) -> np.ndarray:
        return self._cloud_port.Eval(context).xyzs().T

    def _calc_points(self, context, output):
        # Seeded by the time, so the same context always gives the same resample.
        rng = np.random.default_rng([self.cfg.seed, int(round(context.get_time() * 1e6))])
        output.SetFromVector(resample(self._kept(context), self.cfg.num_points, rng).reshape(-1))

    def _calc_count(self, context, output):
        output.SetFromVector([self._cloud_port.Eval(context).size()])
