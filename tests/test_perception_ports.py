"""The perception systems read Drake's free-body state through contract.py's layout: checked
against a real MultibodyPlant's state output (no rendering needed)."""

import numpy as np
from pydrake.geometry import GeometryFrame, SceneGraph
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import SpatialInertia, UnitInertia

from corn_drake.contract import FREE_BODY_STATE_DIM
from corn_drake.builders.student import _pose7_selector
from corn_drake.systems.perception.cameras import CameraAim, look_at


def _free_body_state(X: RigidTransform, v=(0.1, -0.2, 0.3, 0.4, -0.5, 0.6)) -> np.ndarray:
    """The state output of a plant holding one free body at pose X, moving with velocity v."""
    plant = MultibodyPlant(0.0)
    body = plant.AddRigidBody("box", SpatialInertia(1.0, np.zeros(3), UnitInertia.SolidBox(1, 1, 1)))
    plant.Finalize()
    ctx = plant.CreateDefaultContext()
    plant.SetFreeBodyPose(ctx, body, X)
    plant.SetVelocities(ctx, np.asarray(v))
    x = plant.get_state_output_port().Eval(ctx)
    assert x.shape == (FREE_BODY_STATE_DIM,)
    return x


def test_pose7_selector_gives_position_then_quaternion():
    X = RigidTransform(RollPitchYaw(0.3, -0.2, 1.1), [0.05, -0.07, 0.43])
    pose7 = _pose7_selector() @ _free_body_state(X)
    q = X.rotation().ToQuaternion()
    np.testing.assert_allclose(pose7, [*X.translation(), q.w(), q.x(), q.y(), q.z()], atol=1e-12)


def test_camera_aim_looks_at_the_object_position_from_the_state_port():
    sg = SceneGraph()
    source = sg.RegisterSource("rig")
    frame = sg.RegisterFrame(source, GeometryFrame("camera0"))
    eye = [0.458, -0.40, 0.740]
    aim = CameraAim([frame], [eye])
    ctx = aim.CreateDefaultContext()
    X = RigidTransform(RollPitchYaw(0.0, 0.0, 0.7), [0.12, -0.05, 0.43])
    aim.GetInputPort("object_state").FixValue(ctx, _free_body_state(X))
    poses = aim.GetOutputPort("frame_poses").Eval(ctx)
    expected = look_at(eye, X.translation())
    assert poses.value(frame).IsNearlyEqualTo(expected, 1e-12)
