"""The student rollout diagram from diagrams/student_rollout.yaml builds and simulates, and its
observations are the perception chain's (noisy cloud, goal relative to the estimated pose)."""

import numpy as np
import pytest
from pydrake.math import RigidTransform

from corn_drake.diagrams_student import build_student_diagram, load_student_config
from corn_drake.systems.cameras import rendering_available
from corn_drake.systems.pose_tracker import pose7_to_matrix
from corn_drake.transforms import pose9, quat_wxyz_to_matrix

ok, reason = rendering_available()
pytestmark = pytest.mark.skipif(not ok, reason=reason)


def test_yaml_loads_with_the_paper_numbers():
    cfg = load_student_config()
    assert len(cfg.cameras.eyes) == 3 and cfg.cameras.eyes[0] == [0.458, -0.40, 0.740]
    assert cfg.segmentation.num_points == 512 and cfg.observation.cloud_noise_std == 0.005
    assert cfg.tracker.reregister_fitness == 0.6


def test_student_diagram_simulates_and_observes_through_perception():
    from pydrake.systems.analysis import Simulator

    cfg = load_student_config()
    sd = build_student_diagram(cfg)
    d = sd.diagram
    sim = Simulator(d)
    ctx = sim.get_mutable_context()
    d.GetInputPort("controller.action").FixValue(ctx, np.zeros(20))
    plant, scene = sd.scene.plant, sd.scene
    pctx = plant.GetMyMutableContextFromRoot(ctx)
    q0 = np.array([0, -0.5, 0, -2.6, 0, 2.0, 0.8])
    plant.SetPositions(pctx, scene.panda, q0)
    sd.teacher.ik.hold_position(sd.teacher.ik.GetMyMutableContextFromRoot(ctx), q0)
    plant.SetFreeBodyPose(pctx, scene.object_body, RigidTransform([0.05, 0.03, 0.4252]))
    sim.Initialize()
    sim.AdvanceTo(0.3)

    obs = {k: d.GetOutputPort(f"student.{k}").Eval(ctx)
           for k in ("cloud", "hand_state", "robot_state", "previous_action", "goal")}
    assert obs["cloud"].shape == (1536,) and obs["goal"].shape == (9,)
    # The noisy cloud is the segmented cloud plus N(0, 0.005): check the noise's size.
    clean = d.GetSubsystemByName("segmentation").GetOutputPort("points").Eval(
        d.GetSubsystemByName("segmentation").GetMyContextFromRoot(ctx))
    noise = obs["cloud"] - clean
    assert 0.004 < noise.std() < 0.006
    # Points are on the object: near its true position.
    X_true = plant.EvalBodyPoseInWorld(pctx, scene.object_body)
    assert np.linalg.norm(clean.reshape(-1, 3).mean(0) - X_true.translation()) < 0.04
    # The goal is relative to the *estimated* pose (perception.pose), which tracks the truth.
    est = d.GetOutputPort("perception.pose").Eval(ctx)
    goal_pose = sd.teacher.sources["goal_pose"].get_output_port().Eval(
        sd.teacher.sources["goal_pose"].GetMyContextFromRoot(ctx))
    X_est = pose7_to_matrix(est)
    expected = pose9(goal_pose[:3] - X_est[:3, 3], quat_wxyz_to_matrix(goal_pose[3:]) @ X_est[:3, :3].T)
    assert np.allclose(obs["goal"], expected)
    assert np.linalg.norm(est[:3] - X_true.translation()) < 0.005
    assert d.GetOutputPort("perception.status").Eval(ctx)[0] == 1.0
    assert d.GetOutputPort("perception.num_points").Eval(ctx)[0] > 100
