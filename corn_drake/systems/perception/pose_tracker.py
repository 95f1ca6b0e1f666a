"""PoseTracker: the object's pose from segmented clouds by chained ICP (open3d).

Each update registers the new cloud to the previous frame's cloud (point-to-plane; point-to-
point for thin objects, whose few faces make point-to-plane slide) starting from a constant-
velocity guess, chains the result onto the previous pose, then tries to re-register against
the first frame's cloud and takes that answer when its fitness exceeds `reregister_fitness`,
which removes the drift accumulated since the object last looked like the first frame.

Everything the tracker remembers (pose, previous pose, previous and first clouds, status) is
one immutable TrackerState in the context's abstract state, replaced by unrestricted updates
(periodic, at initialization, or forced), so cloning or resetting a context clones or resets
the tracker. Bad input never raises: an empty or non-finite cloud, an ICP with too few
correspondences or an implausible jump keeps the last pose and reports ok = 0.

Inputs: ``object_cloud`` (PointCloud, world frame), ``initial_pose`` (pose7: xyz + wxyz; read
when the tracker (re)initializes, e.g. the known start pose), ``goal_pose`` (pose7).
Outputs: ``pose`` (pose7), ``status`` (STATUS_FIELDS), ``goal`` (GOAL_DIM: goal position minus
estimated position, 6D of R_goal R_est^T, like TeacherObservations' goal).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RotationMatrix
from pydrake.perception import PointCloud
from pydrake.systems.framework import EventStatus, LeafSystem

from corn_drake.contract import GOAL_DIM, POSE7_DIM, POSE7_POSITION, POSE7_QUATERNION
from corn_drake.transforms import pose9, quat_wxyz_to_matrix, rotation_angle

STATUS_FIELDS = ("ok", "fitness", "inlier_rmse", "num_points", "reregistered")


@dataclasses.dataclass(frozen=True)
class TrackerState:
    initialized: bool = False
    X: np.ndarray = dataclasses.field(default_factory=lambda: np.eye(4))  # pose estimate X_WO
    X_prev: np.ndarray = dataclasses.field(default_factory=lambda: np.eye(4))
    prev_cloud: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    ref_cloud: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    X_ref: np.ndarray = dataclasses.field(default_factory=lambda: np.eye(4))
    status: tuple = (0.0, 0.0, 0.0, 0.0, 0.0)


def pose7_to_matrix(p7) -> np.ndarray:
    p7 = np.asarray(p7, float)
    X = np.eye(4)
    X[:3, :3] = quat_wxyz_to_matrix(p7[POSE7_QUATERNION])
    X[:3, 3] = p7[POSE7_POSITION]
    return X


def matrix_to_pose7(X: np.ndarray) -> np.ndarray:
    q = RotationMatrix(X[:3, :3]).ToQuaternion()
    return np.array([*X[:3, 3], q.w(), q.x(), q.y(), q.z()])


def _project_rotation(X: np.ndarray) -> np.ndarray:
    """Nearest proper rotation (chained float products drift off SO(3))."""
    u, _, vt = np.linalg.svd(X[:3, :3])
    R = u @ vt
    if np.linalg.det(R) < 0:
        u[:, -1] *= -1
        R = u @ vt
    Y = X.copy()
    Y[:3, :3] = R
    return Y


def clean_cloud(points, max_points: int, seed: int = 0) -> np.ndarray:
    """Finite rows only, at most max_points of them (a fixed-seed random subset)."""
    p = np.asarray(points, float).reshape(-1, 3)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) > max_points:
        p = p[np.random.default_rng(seed).choice(len(p), max_points, replace=False)]
    return p


def icp(source: np.ndarray, target: np.ndarray, init: np.ndarray, max_distance: float, *,
        point_to_plane: bool, normal_radius: float, max_iterations: int):
    """open3d ICP moving `source` onto `target`; returns (T, fitness, inlier_rmse)."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source))
    tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(target))
    if point_to_plane:
        tgt.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=normal_radius, max_nn=30))
        method = reg.TransformationEstimationPointToPlane()
    else:
        method = reg.TransformationEstimationPointToPoint()
    result = reg.registration_icp(src, tgt, max_distance, init, method,
                                  reg.ICPConvergenceCriteria(max_iteration=max_iterations))
    return np.asarray(result.transformation), float(result.fitness), float(result.inlier_rmse)


def _step_size(A: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    D = np.linalg.inv(A) @ B
    return float(np.linalg.norm(A[:3, 3] - B[:3, 3])), np.rad2deg(rotation_angle(D[:3, :3]))


def initial_state(X0: np.ndarray, cloud: np.ndarray, cfg) -> TrackerState:
    cloud = clean_cloud(cloud, cfg.max_points)
    ok = float(len(cloud) >= cfg.min_points and np.isfinite(X0).all())
    X0 = X0 if np.isfinite(X0).all() else np.eye(4)
    keep = cloud if ok else np.zeros((0, 3))
    return TrackerState(initialized=True, X=X0, X_prev=X0, prev_cloud=keep, ref_cloud=keep,
                        X_ref=X0, status=(ok, 1.0 if ok else 0.0, 0.0, float(len(cloud)), 0.0))


def track_step(state: TrackerState, cloud, cfg, point_to_plane: bool = True) -> TrackerState:
    """One tracker update (pure: returns a new state, never raises on bad clouds)."""
    X_last = state.X
    p = clean_cloud(cloud, cfg.max_points, seed=len(np.asarray(cloud).reshape(-1)))
    n = float(len(p))

    def lost(fitness=0.0, rmse=0.0):
        return dataclasses.replace(state, status=(0.0, fitness, rmse, n, 0.0))

    if len(p) < cfg.min_points:
        return lost()
    if len(state.prev_cloud) < cfg.min_points:
        # Nothing to register against yet (started blind): adopt this cloud at the last pose.
        return dataclasses.replace(state, prev_cloud=p, ref_cloud=p, X_ref=X_last,
                                   status=(0.0, 0.0, 0.0, n, 0.0))
    opts = dict(point_to_plane=point_to_plane, normal_radius=cfg.normal_radius,
                max_iterations=cfg.max_iterations)
    try:
        # Constant-velocity guess: X_pred = X_last X_prev^-1 X_last, so A0 = X_last X_pred^-1.
        A0 = state.X_prev @ np.linalg.inv(X_last)
        A, fitness, rmse = icp(p, state.prev_cloud, A0, cfg.max_correspondence, **opts)
        if not np.isfinite(A).all():
            return lost()
        X_new = _project_rotation(np.linalg.inv(A) @ X_last)
        dt, dr = _step_size(X_last, X_new)
        if fitness < cfg.min_fitness or dt > cfg.max_step_translation or dr > cfg.max_step_rotation_deg:
            return lost(fitness, rmse)
        rereg = 0.0
        if len(state.ref_cloud) >= cfg.min_points:
            B0 = state.X_ref @ np.linalg.inv(X_new)
            B, f_ref, r_ref = icp(p, state.ref_cloud, B0, cfg.reregister_correspondence, **opts)
            if np.isfinite(B).all() and f_ref > cfg.reregister_fitness:
                X_ref_based = _project_rotation(np.linalg.inv(B) @ state.X_ref)
                dt, dr = _step_size(X_last, X_ref_based)
                if dt <= cfg.max_step_translation and dr <= cfg.max_step_rotation_deg:
                    X_new, rereg = X_ref_based, 1.0
    except Exception:  # open3d errors (degenerate clouds) must not end a simulation
        return lost()
    return dataclasses.replace(state, X=X_new, X_prev=X_last, prev_cloud=p,
                               status=(1.0, fitness, rmse, n, rereg))


class PoseTracker(LeafSystem):
    def __init__(self, cfg, *, period: float, offset: float, thin: bool = False):
        super().__init__()
        self.cfg = cfg
        self._point_to_plane = not thin
        self._state_index = self.DeclareAbstractState(AbstractValue.Make(TrackerState()))
        self._cloud = self.DeclareAbstractInputPort("object_cloud", AbstractValue.Make(PointCloud()))
        self._initial_pose = self.DeclareVectorInputPort("initial_pose", POSE7_DIM)
        self._goal_pose = self.DeclareVectorInputPort("goal_pose", POSE7_DIM)
        state_only = {self.abstract_state_ticket(self._state_index)}
        self.DeclareVectorOutputPort("pose", POSE7_DIM, self._calc_pose, prerequisites_of_calc=state_only)
        self.DeclareVectorOutputPort("status", len(STATUS_FIELDS), self._calc_status,
                                     prerequisites_of_calc=state_only)
        self.DeclareVectorOutputPort(
            "goal", GOAL_DIM, self._calc_goal,
            prerequisites_of_calc={self.abstract_state_ticket(self._state_index),
                                   self.input_port_ticket(self._goal_pose.get_index())})
        self.DeclareInitializationUnrestrictedUpdateEvent(self._on_update)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, offset, self._on_update)
        self.DeclareForcedUnrestrictedUpdateEvent(self._on_update)

    # --- state access ------------------------------------------------------------------------
    def tracker_state(self, context) -> TrackerState:
        return context.get_abstract_state(self._state_index).get_value()

    def reset(self, context) -> None:
        """Forget everything: the next update re-initializes from ``initial_pose``."""
        context.get_mutable_abstract_state(self._state_index).set_value(TrackerState())

    def _cloud_points(self, context) -> np.ndarray:
        return self._cloud.Eval(context).xyzs().T

    def next_state(self, context) -> TrackerState:
        state = self.tracker_state(context)
        try:
            cloud = self._cloud_points(context)
        except Exception:
            cloud = np.zeros((0, 3))
        if not state.initialized:
            return initial_state(pose7_to_matrix(self._initial_pose.Eval(context)),
                                 cloud, self.cfg)
        return track_step(state, cloud, self.cfg, self._point_to_plane)

    def _on_update(self, context, state):
        state.get_mutable_abstract_state(self._state_index).set_value(self.next_state(context))
        return EventStatus.Succeeded()

    # --- outputs -----------------------------------------------------------------------------
    def _calc_pose(self, context, output):
        output.SetFromVector(matrix_to_pose7(self.tracker_state(context).X))

    def _calc_status(self, context, output):
        output.SetFromVector(np.asarray(self.tracker_state(context).status, float))

    def _calc_goal(self, context, output):
        X = self.tracker_state(context).X
        g = self._goal_pose.Eval(context)
        output.SetFromVector(pose9(g[POSE7_POSITION] - X[:3, 3],
                                   quat_wxyz_to_matrix(g[POSE7_QUATERNION]) @ X[:3, :3].T))


def pose_error(X_est: np.ndarray, X_true: np.ndarray) -> tuple[float, float]:
    """(translation error in m, rotation error in degrees)."""
    return (float(np.linalg.norm(X_est[:3, 3] - X_true[:3, 3])),
            float(np.rad2deg(rotation_angle(X_est[:3, :3] @ X_true[:3, :3].T))))

