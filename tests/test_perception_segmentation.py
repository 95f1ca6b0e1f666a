"""Segmentation of rendered scenes against the renderer's label image."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from corn_drake.config.student import StudentDiagramConfig
from corn_drake.scene.objects import box_spec
from corn_drake.systems.perception.cameras import rendering_available

ok, reason = rendering_available()
pytestmark = pytest.mark.skipif(not ok, reason=reason)

# Tool at (0, 0, 0.465) pointing straight down (found by IK on our Panda model): the finger
# pads span x in [-0.0105, 0.0105], z in [0.456, 0.51].
Q_HAND_DOWN = [-0.0009, 0.3635, 0.0008, -2.3874, 0.0007, 2.7508, 0.7846]


def _harness(spec=None, **seg):
    from corn_drake.builders.perception_harness import PerceptionHarness

    cfg = StudentDiagramConfig()
    for k, v in seg.items():
        setattr(cfg.segmentation, k, v)
    return PerceptionHarness(cfg, spec)


SCENES = [RigidTransform([0.05, 0.02, 0.425]),
          RigidTransform(RollPitchYaw(0, 0, 0.7), [-0.1, 0.12, 0.425]),
          RigidTransform(RollPitchYaw(0, 0, -0.4), [0.12, -0.15, 0.425])]


def test_geometric_segmentation_precision_and_recall():
    h = _harness()
    for X in SCENES:
        h.set_object(X)
        pr = h.precision_recall()
        assert pr["recall"] >= 0.95, pr
        assert pr["non_object_fraction"] < 0.02, pr
        # The resampled output has exactly num_points rows, all from the kept set.
        pts = h.per.segmentation.GetOutputPort("points").Eval(h.seg_context).reshape(-1, 3)
        assert pts.shape == (512, 3)
        kept = h.segmented_cloud()
        d = np.linalg.norm(pts[:, None] - kept[None], axis=2).min(axis=1)
        assert d.max() < 1e-6


def test_robot_points_removed_when_the_gripper_touches_the_object():
    spec = box_spec([0.09, 0.07, 0.08], 0.3)
    h = _harness(spec)
    h.set_robot(Q_HAND_DOWN)
    # The box's -x face touches the finger pads' +x face.
    X = RigidTransform([0.0105 + 0.045, 0.0, 0.44])
    h.set_object(X)
    labels = h.labels()
    robot_labels = {int(h.scene.plant.GetBodyByName(n).index())
                    for n in ("panda_hand", "panda_leftfinger", "panda_rightfinger")}
    assert np.isin(labels, list(robot_labels)).sum() > 50  # the hand is in view
    pr = h.precision_recall()
    kept_labels = labels[h.segment_indices()]
    assert not np.isin(kept_labels, list(robot_labels)).any()
    assert pr["non_object_fraction"] < 0.02, pr
    assert pr["recall"] >= 0.9, pr  # points within robot_margin of the pads go too


def test_without_the_robot_link_test_the_robot_leaks_in(monkeypatch):
    """Control for the test above: the link test is what removes the hand."""
    import corn_drake.systems.perception.segmentation as segmentation

    # The link test switched off (no point is inside any link); a negative robot_margin did
    # this before the config's bounds refused one.
    monkeypatch.setattr(segmentation, "inside_primitives",
                        lambda points, *args: np.zeros(len(points), dtype=bool))
    spec = box_spec([0.09, 0.07, 0.08], 0.3)
    h = _harness(spec)
    h.set_robot(Q_HAND_DOWN)
    h.set_object(RigidTransform([0.0105 + 0.045, 0.0, 0.44]))
    assert h.precision_recall()["non_object_fraction"] > 0.02


def test_ground_truth_mode_equals_the_label_image():
    h = _harness(mode="ground_truth")
    h.set_object(SCENES[1])
    labels, pts = h.labels(), h.merged_points()
    expected = pts[(labels == h.object_label) & np.isfinite(pts).all(axis=1)]
    assert np.array_equal(h.segmented_cloud(), expected)


def test_nothing_in_view_gives_an_empty_cloud_and_zero_points():
    h = _harness()
    h.set_object(RigidTransform([3.0, 3.0, 0.0]))  # off the table, out of every view
    assert h.segmented_cloud().shape == (0, 3)
    n = h.per.segmentation.GetOutputPort("num_points").Eval(h.seg_context)
    pts = h.per.segmentation.GetOutputPort("points").Eval(h.seg_context)
    assert n[0] == 0 and not pts.any()


def test_d435_resolution_works_after_voxel_thinning():
    """640 x 480 per camera (a real D435): thinned to 4 mm voxels, still only object points."""
    from corn_drake.builders.perception_harness import PerceptionHarness

    cfg = StudentDiagramConfig()
    cfg.cameras.camera.width, cfg.cameras.camera.height = 640, 480
    h = PerceptionHarness(cfg)
    h.set_object(SCENES[0])
    pr = h.precision_recall()
    assert h.per.segmentation.voxel > 0
    assert pr["non_object_fraction"] < 0.02 and pr["kept"] > 500, pr
