"""Camera rig: depth images at the configured size, world-frame clouds on the object's surface,
and tracking cameras that follow the object."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from corn_drake.config.student import StudentDiagramConfig
from corn_drake.systems.perception.cameras import look_at, rendering_available

ok, reason = rendering_available()
pytestmark = pytest.mark.skipif(not ok, reason=reason)


def _harness(mode="fixed", **camera):
    """A harness whose rig is in `mode`, with Drake CameraConfig fields set from `camera`."""
    from corn_drake.builders.perception_harness import PerceptionHarness

    cfg = StudentDiagramConfig()
    cfg.cameras.mode = mode
    for k, v in camera.items():
        setattr(cfg.cameras.camera, k, v)
    return PerceptionHarness(cfg)


def test_look_at_points_the_optical_axis_at_the_target():
    X = look_at([0.458, -0.40, 0.740], [0.0, 0.0, 0.45])
    z = X.rotation().matrix()[:, 2]
    d = np.array([-0.458, 0.40, -0.29])
    assert np.allclose(z, d / np.linalg.norm(d))
    # Image "down" (+y) must point downwards in the world, or images come out upside down.
    assert X.rotation().matrix()[2, 1] < 0


def test_three_depth_images_and_clouds_on_the_object_surface():
    h = _harness(width=96, height=72)
    X = RigidTransform(RollPitchYaw(0, 0, 0.4), [0.03, -0.05, 0.425])
    h.set_object(X)
    images = h.depth_images()
    assert [im.shape for im in images] == [(72, 96)] * 3
    for im in images:
        # Background beyond z_far is +inf; the table and object are finite and in range.
        assert np.isinf(im).any() and np.isfinite(im).any()
        assert np.nanmin(im[np.isfinite(im)]) > 0.3
    pts, labels = h.merged_points(), h.labels()
    obj = pts[labels == h.object_label]
    assert len(obj) > 100
    # Back in the object frame every object point lies on the 0.09 x 0.07 x 0.05 box surface.
    # (Without the half-pixel principal-point correction in back_projection_info points land
    # up to 4 mm off at this resolution, which this tolerance rejects.)
    local = (obj - X.translation()) @ X.rotation().matrix()
    half = np.array([0.045, 0.035, 0.025])
    assert (np.abs(local) <= half + 5e-4).all()
    assert np.abs(np.abs(local) - half).min(axis=1).max() < 5e-4
    # Table-top points (label 0 is the world body; its side faces are in view too) are flat.
    table = pts[labels == 0]
    top = table[(np.abs(table[:, 0]) < 0.19) & (np.abs(table[:, 1]) < 0.24) & (table[:, 2] > 0.39)]
    assert len(top) > 1000 and np.abs(top[:, 2] - 0.4).max() < 5e-4


def test_tracking_cameras_keep_the_object_centred():
    h = _harness(mode="tracking", width=32, height=32)
    for xy in ([0.12, 0.15], [-0.12, -0.15]):
        h.set_object(RigidTransform([xy[0], xy[1], 0.425]))
        for im, lab in zip(h.depth_images(), np.split(h.labels(), 3)):
            mask = lab.reshape(32, 32) == h.object_label
            # The object fills a good part of the narrow view and its centroid is central.
            assert mask.mean() > 0.1
            v, u = np.nonzero(mask)
            assert abs(u.mean() - 15.5) < 5 and abs(v.mean() - 15.5) < 5
