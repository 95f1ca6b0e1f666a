"""The tracker keeps its last pose and reports ok = 0 on bad input, and never raises.

Each case runs through the LeafSystem's own update event (ExecuteForcedEvents), which is what
the simulator runs; the last test does it inside a running Simulator.
"""

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.perception import BaseField, Fields, PointCloud

from corn_drake.config.student import StudentDiagramConfig, TrackerConfig
from corn_drake.scene.objects import box_spec
from corn_drake.systems.perception.cameras import rendering_available
from corn_drake.systems.perception.pose_tracker import PoseTracker, matrix_to_pose7

X0 = RigidTransform([0.02, -0.03, 0.45]).GetAsMatrix4()


def _cloud(points) -> AbstractValue:
    points = np.asarray(points, np.float32).reshape(-1, 3)
    pc = PointCloud(len(points), Fields(BaseField.kXYZs))
    if len(points):
        pc.mutable_xyzs()[:] = points.T
    return AbstractValue.Make(pc)


def _box_points():
    spec = box_spec([0.09, 0.07, 0.05], 0.3, cloud_points=1500)
    return spec.cloud[spec.cloud[:, 5] > -0.5, :3] + X0[:3, 3]  # no bottom face


@pytest.fixture
def tracker():
    """A tracker initialized at X0 on a good cloud."""
    sys = PoseTracker(TrackerConfig(), period=0.1, offset=0.0)
    ctx = sys.CreateDefaultContext()
    sys.GetInputPort("initial_pose").FixValue(ctx, matrix_to_pose7(X0))
    sys.GetInputPort("goal_pose").FixValue(ctx, matrix_to_pose7(X0))
    sys.GetInputPort("object_cloud").FixValue(ctx, _cloud(_box_points()))
    sys.ExecuteForcedEvents(ctx)
    assert sys.GetOutputPort("status").Eval(ctx)[0] == 1.0
    return sys, ctx


def _update_with(sys, ctx, points):
    pose_before = sys.GetOutputPort("pose").Eval(ctx).copy()
    sys.GetInputPort("object_cloud").FixValue(ctx, _cloud(points))
    sys.ExecuteForcedEvents(ctx)  # must not raise
    return pose_before, sys.GetOutputPort("pose").Eval(ctx), sys.GetOutputPort("status").Eval(ctx)


def test_empty_cloud_keeps_the_pose(tracker):
    before, after, status = _update_with(*tracker, np.zeros((0, 3)))
    assert np.array_equal(before, after) and status[0] == 0.0 and status[3] == 0


def test_nan_cloud_keeps_the_pose(tracker):
    before, after, status = _update_with(*tracker, np.full((500, 3), np.nan))
    assert np.array_equal(before, after) and status[0] == 0.0
    assert np.isfinite(after).all()


def test_icp_without_correspondences_keeps_the_pose(tracker):
    # The object "jumps" 0.5 m: no point is within the correspondence distance.
    before, after, status = _update_with(*tracker, _box_points() + [0.5, 0.0, 0.0])
    assert np.array_equal(before, after) and status[0] == 0.0 and status[1] < 0.3


def test_icp_on_a_shapeless_blob_keeps_the_pose(tracker):
    # Random points where the object was: ICP "converges" somewhere implausible or poorly.
    blob = X0[:3, 3] + np.random.default_rng(0).normal(0, 0.05, (800, 3))
    before, after, status = _update_with(*tracker, blob)
    assert np.array_equal(before, after) and status[0] == 0.0


def test_recovers_when_the_object_is_seen_again(tracker):
    sys, ctx = tracker
    _update_with(sys, ctx, np.zeros((0, 3)))
    _, after, status = _update_with(sys, ctx, _box_points())
    assert status[0] == 1.0 and np.allclose(after[:3], X0[:3, 3], atol=1e-3)


def test_state_lives_in_the_context(tracker):
    """A cloned context carries the tracker's memory; updating one leaves the other alone."""
    sys, ctx = tracker
    clone = ctx.Clone()
    _update_with(sys, ctx, _box_points() + [0.01, 0.0, 0.0])
    moved = sys.GetOutputPort("pose").Eval(ctx)
    kept = sys.GetOutputPort("pose").Eval(clone)
    assert abs(moved[0] - X0[0, 3] - 0.01) < 1e-3 and abs(kept[0] - X0[0, 3]) < 1e-9
    sys.reset(ctx)
    assert not sys.tracker_state(ctx).initialized and sys.tracker_state(clone).initialized


@pytest.mark.skipif(not rendering_available()[0], reason=rendering_available()[1])
def test_object_leaving_the_view_inside_a_simulation():
    from pydrake.systems.analysis import Simulator

    from corn_drake.builders.student import build_student_diagram

    cfg = StudentDiagramConfig()
    cfg.teacher.randomization.torque_noise_std = 0.0
    sd = build_student_diagram(cfg)
    sim = Simulator(sd.diagram)
    ctx = sim.get_mutable_context()
    sd.diagram.GetInputPort("controller.action").FixValue(ctx, np.zeros(20))
    plant, scene = sd.scene.plant, sd.scene
    pctx = plant.GetMyMutableContextFromRoot(ctx)
    plant.SetPositions(pctx, scene.panda, [0, -0.5, 0, -2.6, 0, 2.0, 0.8])  # arm out of the way
    sd.teacher.ik.hold_position(sd.teacher.ik.GetMyMutableContextFromRoot(ctx),
                                plant.GetPositions(pctx, scene.panda))
    plant.SetFreeBodyPose(pctx, scene.object_body, RigidTransform([0.05, 0.0, 0.4252]))
    sim.Initialize()
    sim.AdvanceTo(0.2)
    status = sd.diagram.GetOutputPort("perception.status").Eval(ctx)
    pose = sd.diagram.GetOutputPort("perception.pose").Eval(ctx).copy()
    assert status[0] == 1.0 and abs(pose[0] - 0.05) < 0.005
    # Teleport the object far out of every view (it falls; nothing to see).
    plant.SetFreeBodyPose(pctx, scene.object_body, RigidTransform([3.0, 3.0, 0.5]))
    sim.AdvanceTo(0.4)
    status = sd.diagram.GetOutputPort("perception.status").Eval(ctx)
    assert status[0] == 0.0 and status[3] == 0
    assert np.array_equal(sd.diagram.GetOutputPort("perception.pose").Eval(ctx), pose)
    goal = sd.diagram.GetOutputPort("student.goal").Eval(ctx)
    assert np.isfinite(goal).all()
