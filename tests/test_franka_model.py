"""The Panda model: offline parsing, limits, and FK against the published DH table."""

import xml.etree.ElementTree as ET

import numpy as np
import pytest
from pydrake.geometry import Box
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant, AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder

from corn_drake import MODELS_DIR
from corn_drake.scene.franka import EFFORT_LIMITS, JOINT_LOWER, JOINT_UPPER, make_controller_plant
from corn_drake.scene.gripper import PANDA_URDF, gripper_boxes


def _dh(a, d, alpha, theta):
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    return np.array([[ct, -st, 0, a], [st * ca, ct * ca, -sa, -d * sa],
                     [st * sa, ct * sa, ca, d * ca], [0, 0, 0, 1]])


def _published_fk(q):
    """Franka's modified-DH table, flange 0.107, hand -45 deg about z, TCP 0.1034."""
    table = [(0, 0.333, 0), (0, 0, -np.pi / 2), (0, 0.316, np.pi / 2), (0.0825, 0, np.pi / 2),
             (-0.0825, 0.384, -np.pi / 2), (0, 0, np.pi / 2), (0.088, 0, np.pi / 2)]
    T = np.eye(4)
    for (a, d, alpha), theta in zip(table, q):
        T = T @ _dh(a, d, alpha, theta)
    T = T @ _dh(0, 0.107, 0, 0) @ _dh(0, 0, 0, -np.pi / 4) @ _dh(0, 0.1034, 0, 0)
    return T


def test_exactly_one_model_file_parses_without_package_map():
    files = [p for p in (MODELS_DIR / "franka_panda").iterdir() if p.suffix in (".urdf", ".sdf")]
    assert [p.name for p in files] == ["panda.urdf"]
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModels(str(files[0]))
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("panda_link0"))
    plant.Finalize()
    assert plant.num_positions() == 7 and plant.num_actuators() == 7  # fingers fixed closed
    for name in ("panda_link0", "panda_hand", "panda_tool"):
        plant.GetFrameByName(name)


def test_limits_match_published_figures():
    plant = make_controller_plant()
    for i in range(7):
        joint = plant.GetJointByName(f"panda_joint{i + 1}")
        assert joint.position_lower_limits()[0] == pytest.approx(JOINT_LOWER[i])
        assert joint.position_upper_limits()[0] == pytest.approx(JOINT_UPPER[i])
        actuator = plant.GetJointActuatorByName(f"panda_motor{i + 1}")
        assert actuator.effort_limit() == pytest.approx(EFFORT_LIMITS[i])
    np.testing.assert_allclose(EFFORT_LIMITS, [87, 87, 87, 87, 12, 12, 12])


def test_tool_fk_matches_dh_table():
    plant = make_controller_plant()
    ctx = plant.CreateDefaultContext()
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = rng.uniform(JOINT_LOWER, JOINT_UPPER)
        plant.SetPositions(ctx, q)
        X = plant.CalcRelativeTransform(ctx, plant.world_frame(), plant.GetFrameByName("panda_tool"))
        np.testing.assert_allclose(X.GetAsMatrix4(), _published_fk(q), atol=1e-9)
    hand = plant.CalcRelativeTransform(ctx, plant.GetFrameByName("panda_hand"),
                                       plant.GetFrameByName("panda_tool"))
    np.testing.assert_allclose(hand.translation(), [0, 0, 0.1034], atol=1e-12)


def test_gripper_boxes_are_the_simulated_collision_boxes():
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    Parser(plant).AddModels(str(PANDA_URDF))
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("panda_link0"))
    plant.Finalize()
    inspector = scene_graph.model_inspector()
    ctx = plant.CreateDefaultContext()
    tool = plant.GetFrameByName("panda_tool")
    sim_boxes = {}
    for body in ("panda_hand", "panda_leftfinger", "panda_rightfinger"):
        b = plant.GetBodyByName(body)
        X_TBody = plant.CalcRelativeTransform(ctx, tool, b.body_frame())
        for gid in plant.GetCollisionGeometriesForBody(b):
            shape = inspector.GetShape(gid)
            assert isinstance(shape, Box)
            X = X_TBody @ inspector.GetPoseInFrame(gid)
            sim_boxes[inspector.GetName(gid).split("::")[-1]] = (shape.size() / 2, X.GetAsMatrix4())
    boxes = gripper_boxes()
    assert {b.name for b in boxes} == set(sim_boxes)
    for b in boxes:
        half, X = sim_boxes[b.name]
        np.testing.assert_allclose(b.half_extents, half)
        np.testing.assert_allclose(b.X_TB, X, atol=1e-12)
    # Closed fingers: the two pads touch at the tool's y = 0 and reach just past the TCP.
    tips = [b.X_TB[2, 3] + b.half_extents[2] for b in boxes if "finger" in b.name]
    assert all(0.0 < t < 0.02 for t in tips)


def test_gripper_boxes_reject_a_non_box_hand(tmp_path):
    tree = ET.parse(PANDA_URDF)
    for link in tree.getroot().iter("link"):
        if link.get("name") == "panda_leftfinger":
            geom = link.find("collision/geometry")
            geom.remove(geom.find("box"))
            ET.SubElement(geom, "sphere", radius="0.01")
    bad = tmp_path / "panda.urdf"
    tree.write(bad)
    with pytest.raises(ValueError, match="not a box"):
        gripper_boxes(bad)
