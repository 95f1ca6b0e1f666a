"""The student rollout diagram from diagrams/student_rollout.yaml builds and simulates, and its
observations are the perception chain's (noisy cloud, goal relative to the estimated pose)."""

import numpy as np
import pytest
from pydrake.math import RigidTransform

from corn_drake.contract import ACTION_DIM
from corn_drake.builders.student import build_student_diagram
from corn_drake.config.plumbing.diagram_files import load_student_config
from corn_drake.systems.perception.cameras import rendering_available
from corn_drake.systems.perception.pose_tracker import pose7_to_matrix
from corn_drake.transforms import pose9, quat_wxyz_to_matrix

ok, reason = rendering_available()
pytestmark = pytest.mark.skipif(not ok, reason=reason)


def test_yaml_loads_with_the_paper_numbers():
    cfg = load_student_config()
    assert len(cfg.cameras.eyes) == 3 and cfg.cameras.eyes[0] == [0.458, -0.40, 0.740]
    assert cfg.segmentation.num_points == 512
    # The paper's N(0, 0.005) cloud and goal noise act on inputs normalised by 0.4 m.
    assert cfg.observation.cloud_noise_std == pytest.approx(0.005 * 0.4)
    assert cfg.observation.goal_noise_std == pytest.approx(0.005 * 0.4)
    assert cfg.tracker.reregister_fitness == 0.6


def _simulated_student(cfg, seconds=0.3):
    """The student diagram with the arm aside and a box on the table, simulated `seconds`."""
    from pydrake.systems.analysis import Simulator

    sd = build_student_diagram(cfg)
    sim = Simulator(sd.diagram)
    ctx = sim.get_mutable_context()
    sd.diagram.GetInputPort("controller.action").FixValue(ctx, np.zeros(20))
    plant, scene = sd.scene.plant, sd.scene
    pctx = plant.GetMyMutableContextFromRoot(ctx)
    q0 = np.array([0, -0.5, 0, -2.6, 0, 2.0, 0.8])
    plant.SetPositions(pctx, scene.panda, q0)
    sd.teacher.ik.hold_position(sd.teacher.ik.GetMyMutableContextFromRoot(ctx), q0)
    plant.SetFreeBodyPose(pctx, scene.object_body, RigidTransform([0.05, 0.03, 0.4252]))
    sim.Initialize()
    sim.AdvanceTo(seconds)
    return sd, ctx


def _clean(sd, ctx, system, port):
    s = sd.diagram.GetSubsystemByName(system)
    return s.GetOutputPort(port).Eval(s.GetMyContextFromRoot(ctx))


def test_student_diagram_simulates_and_observes_through_perception():
    cfg = load_student_config()
    sd, ctx = _simulated_student(cfg)
    d, plant, scene = sd.diagram, sd.scene.plant, sd.scene
    pctx = plant.GetMyContextFromRoot(ctx)

    obs = {k: d.GetOutputPort(f"student.{k}").Eval(ctx)
           for k in ("cloud", "hand_state", "robot_state", "previous_action", "goal")}
    assert obs["cloud"].shape == (1536,) and obs["goal"].shape == (9,)
    # The noisy cloud is the segmented cloud plus N(0, 0.002 m): check the noise's size.
    clean = _clean(sd, ctx, "segmentation", "points")
    noise = obs["cloud"] - clean
    assert 0.0018 < noise.std() < 0.0022
    # Points are on the object: near its true position.
    X_true = plant.EvalBodyPoseInWorld(pctx, scene.object_body)
    assert np.linalg.norm(clean.reshape(-1, 3).mean(0) - X_true.translation()) < 0.04
    # The goal is relative to the *estimated* pose (perception.pose), which tracks the truth.
    est = d.GetOutputPort("perception.pose").Eval(ctx)
    goal_pose = sd.teacher.sources["goal_pose"].get_output_port().Eval(
        sd.teacher.sources["goal_pose"].GetMyContextFromRoot(ctx))
    X_est = pose7_to_matrix(est)
    expected = pose9(goal_pose[:3] - X_est[:3, 3], quat_wxyz_to_matrix(goal_pose[3:]) @ X_est[:3, :3].T)
    # Goal noise (2 mm) on the position only.
    assert np.allclose(obs["goal"][:3], expected[:3], atol=0.01)
    assert np.allclose(obs["goal"][3:], expected[3:])
    assert np.linalg.norm(est[:3] - X_true.translation()) < 0.005
    assert d.GetOutputPort("perception.status").Eval(ctx)[0] == 1.0
    assert d.GetOutputPort("perception.num_points").Eval(ctx)[0] > 100


def test_student_noise_has_the_papers_size_in_metres_and_is_reseeded_per_episode():
    """Cloud and goal-position noise: N(0, 0.005) in normalised units = 2 mm; the rotation part
    of the goal stays clean. reseed_random_sources (called at every episode's reset) gives new
    noise for each draw from an episode RNG, and the same noise for the same seed."""
    from corn_drake.builders.teacher import reseed_random_sources

    sd, ctx = _simulated_student(load_student_config(), seconds=0.1)
    d = sd.diagram
    clean_cloud = _clean(sd, ctx, "segmentation", "points")
    clean_goal = _clean(sd, ctx, "pose_tracker", "goal")

    def noise(rng):
        assert reseed_random_sources(d, ctx, rng) >= 2  # the cloud and goal sources at least
        return (d.GetOutputPort("student.cloud").Eval(ctx) - clean_cloud,
                d.GetOutputPort("student.goal").Eval(ctx) - clean_goal)

    episodes = np.random.default_rng(7)
    draws = [noise(episodes) for _ in range(150)]  # 150 consecutive episodes of one env
    cloud_noise = np.concatenate([c for c, _ in draws])
    goal_noise = np.array([g for _, g in draws])
    assert 0.0019 < cloud_noise.std() < 0.0021 and abs(cloud_noise.mean()) < 1e-4
    assert 0.0018 < goal_noise[:, :3].std() < 0.0022
    assert np.all(goal_noise[:, 3:] == 0)
    # Consecutive episodes differ; so do two envs' (different seeds); a seed reproduces.
    assert not np.allclose(draws[0][0], draws[1][0]) and not np.allclose(draws[0][1], draws[1][1])
    a, b = noise(np.random.default_rng(1)), noise(np.random.default_rng(2))
    assert not np.allclose(a[0], b[0])
    again = noise(np.random.default_rng(1))
    np.testing.assert_array_equal(again[0], a[0])
    np.testing.assert_array_equal(again[1], a[1])


def test_negative_noise_std_is_named():
    cfg = load_student_config()
    cfg.observation.goal_noise_std = -0.002
    from corn_drake.errors import InputError

    with pytest.raises(InputError, match="goal_noise_std"):
        build_student_diagram(cfg)


def test_tracker_updates_once_per_policy_step_at_the_clocks_perception_offset():
    """The tracker has no timing settings of its own: it follows the physics config's clock
    (here a 0.05 s policy period, 4 physics steps), a quarter step after each boundary."""
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import EventStatus

    from corn_drake.timing import clock_of

    cfg = load_student_config()
    cfg.teacher.scene.physics.policy_period = 0.05
    clock = clock_of(cfg.teacher.scene.physics)
    sd = build_student_diagram(cfg)
    tracker = sd.perception.tracker
    sim = Simulator(sd.diagram)
    ctx = sim.get_mutable_context()
    sd.diagram.GetInputPort("controller.action").FixValue(ctx, np.zeros(ACTION_DIM))
    tctx = tracker.GetMyContextFromRoot(ctx)
    updates, last, step_start = [], [None], [0.0]

    def monitor(root):
        # The monitor runs at the end of each step; a timed update at t is applied at the start
        # of the step that begins at t, so a new state dates from the step's start.
        state = tracker.tracker_state(tctx)
        if state is not last[0]:  # every update stores a new TrackerState
            updates.append(step_start[0])
            last[0] = state
        step_start[0] = root.get_time()
        return EventStatus.Succeeded()

    sim.set_monitor(monitor)
    sim.Initialize()
    sim.AdvanceTo(0.2)
    expected = [0.0] + [clock.perception_offset + n * clock.period for n in range(4)]
    np.testing.assert_allclose(updates, expected, atol=1e-12)
