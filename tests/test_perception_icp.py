"""ICP recovers a known rigid transform of a partial object cloud (no rendering needed)."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from corn_drake.config.student import TrackerConfig
from corn_drake.scene.objects import box_spec
from corn_drake.systems.perception.pose_tracker import icp, initial_state, pose_error, track_step


def _partial_box_cloud(size, seed=0):
    """Dense surface samples of a box with the faces a camera above -x,-y would not see cut."""
    spec = box_spec(size, 0.3, cloud_points=4000, seed=seed)
    pts, normals = spec.cloud[:, :3], spec.cloud[:, 3:]
    visible = normals @ np.array([0.6, 0.5, 0.62]) > 0  # faces towards one eye direction
    return pts[visible] + [0.02, -0.03, 0.45]


def _known_motion():
    return RigidTransform(RollPitchYaw(0.0, 0.0, np.deg2rad(6.0)), [0.012, -0.008, 0.0])


@pytest.mark.parametrize("point_to_plane", [True, False])
def test_icp_recovers_a_known_transform(point_to_plane):
    target = _partial_box_cloud([0.09, 0.07, 0.05])
    M = _known_motion().GetAsMatrix4()
    # Rotate about the cloud's centre so the motion is a push, not a swing about the origin.
    c = target.mean(axis=0)
    T = np.eye(4)
    T[:3, :3] = M[:3, :3]
    T[:3, 3] = c + M[:3, 3] - M[:3, :3] @ c
    source = target @ T[:3, :3].T + T[:3, 3]
    # ICP moves the source back onto the target: the answer is T^-1.
    A, fitness, rmse = icp(source, target, np.eye(4), 0.03, point_to_plane=point_to_plane,
                           normal_radius=0.02, max_iterations=60)
    dt, dr = pose_error(A, np.linalg.inv(T))
    assert dt < 0.002 and dr < 1.0, (dt, dr)
    assert fitness > 0.95


def test_tracker_step_chains_the_motion_onto_the_pose():
    cfg = TrackerConfig()
    X0 = RigidTransform([0.02, -0.03, 0.45]).GetAsMatrix4()
    local = _partial_box_cloud([0.09, 0.07, 0.05]) - X0[:3, 3]  # object-frame points
    state = initial_state(X0, local + X0[:3, 3], cfg)
    X1 = X0 @ RigidTransform(RollPitchYaw(0, 0, np.deg2rad(4.0)), [0.006, 0.004, 0.0]).GetAsMatrix4()
    state = track_step(state, local @ X1[:3, :3].T + X1[:3, 3], cfg)
    assert state.status[0] == 1.0
    dt, dr = pose_error(state.X, X1)
    assert dt < 0.002 and dr < 1.0, (dt, dr)
