"""TeacherEnv: observation layout, reset re-randomization, bad input, termination."""

import numpy as np
import pytest

from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.config.plumbing.loader import load_config
from corn_drake.errors import InputError
from corn_drake.rl.envs.teacher_env import TeacherEnv
from corn_drake.scene.objects import ObjectSpec, box_spec
from corn_drake.config.task import PlanarGoal, PushFromHandGoal

EXPECTED_SHAPES = {"cloud": (512, 3), "hand_state": (9,), "robot_state": (14,),
                   "previous_action": (20,), "goal": (9,), "physics": (5,),
                   "object_keypoints": (24,)}


def _task(name: str) -> TeacherDiagramConfig:
    """The base diagram with the task overlay diagrams/tasks/NAME.yaml on top."""
    from corn_drake.config.plumbing.diagram_files import load_teacher_config

    return load_teacher_config(name)


@pytest.fixture(scope="module")
def env():
    return TeacherEnv()


def test_observation_keys_shapes_and_contents(env):
    obs, info = env.reset(seed=0)
    assert {k: v.shape for k, v in obs.items()} == EXPECTED_SHAPES
    assert all(np.isfinite(v).all() for v in obs.values())
    assert env.observation_space.contains(obs)
    # The cloud is the object's surface sample at its current pose: centred on the object.
    p0 = env.episode.initial_object_pose[:3]
    assert np.linalg.norm(obs["cloud"].mean(0) - p0) < 0.02
    # Goal is relative: goal position minus object position.
    np.testing.assert_allclose(obs["goal"][:3], env.episode.goal_pose[:3] - p0, atol=1e-5)
    np.testing.assert_allclose(obs["physics"], env.episode.physics.as_observation(), rtol=1e-6)
    assert np.all(obs["previous_action"] == 0)
    # Keypoints are the object's box corners at its pose: their centre is the object's origin.
    np.testing.assert_allclose(obs["object_keypoints"].reshape(8, 3).mean(0), p0, atol=1e-5)
    # Hand-state rotation columns are orthonormal.
    c0, c1 = obs["hand_state"][3:6], obs["hand_state"][6:9]
    assert abs(np.linalg.norm(c0) - 1) < 1e-5 and abs(c0 @ c1) < 1e-5
    obs, reward, terminated, truncated, info = env.step(np.zeros(20))
    assert np.isfinite(reward) and not truncated
    # previous_action reports the physical action (zero action = mid-range gains).
    np.testing.assert_allclose(obs["previous_action"][6:13], 105.0)


def test_reset_rerandomizes_without_rebuilding(env):
    diagram = env.diagram
    samples = []
    for seed in (1, 2):
        env.reset(seed=seed)
        samples.append((env.episode.physics, env.episode.initial_object_pose,
                        env.episode.goal_pose))
    assert env.diagram is diagram
    (a, pa, ga), (b, pb, gb) = samples
    assert a.mass != b.mass and a.table_friction != b.table_friction
    assert not np.allclose(pa, pb) and not np.allclose(ga, gb)
    for phys in (a, b):
        assert 0.1 <= phys.mass <= 0.5 and 0.3 <= phys.table_friction <= 0.8
        assert 1.0 <= phys.finger_friction <= 1.5 and 0.7 <= phys.object_friction <= 1.0
    # Same seed, same episode.
    env.reset(seed=1)
    np.testing.assert_allclose(env.episode.initial_object_pose, pa)
    # The goal is at least 5.5 cm from the start and the mass is in the plant context.
    assert np.linalg.norm(pa[:2] - ga[:2]) >= 0.055
    ctx = env.scene.plant.GetMyContextFromRoot(env.context)
    assert env.scene.object_body.get_mass(ctx) == pytest.approx(a.mass)


def test_nan_action_raises_and_does_not_poison_the_state(env):
    env.reset(seed=4)
    env.step(np.zeros(20))
    t, x = env.context.get_time(), env.scene.plant.GetPositionsAndVelocities(env.plant_context).copy()
    with pytest.raises(ValueError, match="non-finite"):
        env.step(np.full(20, np.nan))
    assert env.context.get_time() == t
    np.testing.assert_array_equal(env.scene.plant.GetPositionsAndVelocities(env.plant_context), x)
    obs, *_ = env.step(np.zeros(20))
    assert all(np.isfinite(v).all() for v in obs.values())


def test_episode_truncates_at_the_step_limit():
    cfg = TeacherDiagramConfig()
    cfg.task.episode_steps = 5
    env = TeacherEnv(cfg)
    env.reset(seed=0)
    flags = [env.step(np.zeros(20))[3] for _ in range(5)]
    assert flags == [False] * 4 + [True]


def test_object_leaving_the_workspace_terminates(env):
    env.reset(seed=0)
    plant = env.scene.plant
    from pydrake.math import RigidTransform
    plant.SetFreeBodyPose(env.plant_context, env.scene.object_body, RigidTransform([0.0, 0.0, 0.1]))
    _, _, terminated, _, info = env.step(np.zeros(20))
    assert terminated and info["status"]["out_of_workspace"] == 1.0


def test_unknown_config_key_is_named(tmp_path):
    bad = tmp_path / "teacher.yaml"
    bad.write_text("scene:\n  physics:\n    time_stepp: 0.01\n")
    with pytest.raises(ValueError, match="time_stepp"):
        load_config(TeacherDiagramConfig, bad)
    with pytest.raises(FileNotFoundError, match="nowhere.yaml"):
        load_config(TeacherDiagramConfig, tmp_path / "nowhere.yaml")
    with pytest.raises(ValueError, match="bogus"):
        load_config(TeacherDiagramConfig, text="bogus: 1")


def test_missing_mesh_path_is_named(tmp_path):
    base = box_spec([0.05, 0.05, 0.05], 0.2)
    with pytest.raises(FileNotFoundError, match="hull7.obj"):
        ObjectSpec(name="x", mass=0.2, unit_inertia=base.unit_inertia, com=base.com,
                   cloud=base.cloud, stable_poses=base.stable_poses, radius=base.radius,
                   bbox_corners=base.bbox_corners, hull_paths=[tmp_path / "hull7.obj"])


def test_planar_goals_keep_the_resting_face_and_distance():
    from corn_drake.transforms import quat_wxyz_to_matrix

    cfg = _task("planar")
    assert isinstance(cfg.task.goal, PlanarGoal) and cfg.task.name == "planar"
    env = TeacherEnv(cfg)
    for seed in range(5):
        env.reset(seed=seed)
        start, goal = env.episode.initial_object_pose, env.episode.goal_pose
        distance = np.linalg.norm(goal[:2] - start[:2])
        assert 0.1 - 1e-9 <= distance <= 0.2 + 1e-9
        assert goal[2] == pytest.approx(start[2])
        R0, Rg = quat_wxyz_to_matrix(start[3:]), quat_wxyz_to_matrix(goal[3:])
        # Same face down: the world z axis maps to the same object-frame direction.
        np.testing.assert_allclose(R0.T @ [0, 0, 1], Rg.T @ [0, 0, 1], atol=1e-9)
        yaw = np.arccos(np.clip((np.trace(Rg @ R0.T) - 1) / 2, -1, 1))
        assert yaw <= np.pi / 2 + 1e-9


def test_object_scale_is_randomized_through_the_context():
    cfg = TeacherDiagramConfig()
    cfg.randomization.object_radius = [0.05, 0.10]
    env = TeacherEnv(cfg)
    base = np.array(cfg.scene.object.size)
    sizes = []
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        scale = env.episode.physics.scale
        assert 0.05 <= scale * env.scene.object_spec.radius <= 0.10
        sg = env.scene.scene_graph
        inspector = sg.get_query_output_port().Eval(sg.GetMyContextFromRoot(env.context)).inspector()
        size = inspector.GetShape(env.scene.object_geometries[0]).size()
        np.testing.assert_allclose(size, scale * base, rtol=1e-9)
        sizes.append(size[0])
        # The scaled object rests where its scaled stable pose puts it, and the cloud matches.
        z0 = env.episode.initial_object_pose[2]
        for _ in range(5):
            obs, *_ = env.step(np.zeros(20))
        z1 = env.scene.plant.EvalBodyPoseInWorld(env.plant_context, env.scene.object_body).translation()[2]
        assert abs(z1 - z0) < 0.002
        extent = np.ptp(obs["cloud"], axis=0)
        assert extent.max() <= scale * np.linalg.norm(base) + 1e-6
    assert len(set(np.round(sizes, 6))) == 3


def test_near_start_task_puts_the_tool_just_above_the_table_beside_the_object():
    from corn_drake.scene.objects import TABLE_TOP_Z

    cfg = _task("planar_near")
    env = TeacherEnv(cfg)
    tool = env.scene.plant.GetFrameByName("panda_tool")
    for seed in range(6):
        env.reset(seed=seed)
        X = tool.CalcPoseInWorld(env.plant_context)
        p_obj = env.episode.initial_object_pose[:3]
        # Clear of the table but low enough to push without a long approach, pointing down.
        assert TABLE_TOP_Z + 0.03 <= X.translation()[2] <= TABLE_TOP_Z + 0.12
        assert X.rotation().matrix()[2, 2] < -0.95
        assert np.linalg.norm(X.translation()[:2] - p_obj[:2]) >= 0.08 - 1e-9


def test_push_task_puts_the_goal_beyond_the_object_as_seen_from_the_hand():
    cfg = _task("push")
    t, g = cfg.task, cfg.task.goal
    assert isinstance(g, PushFromHandGoal) and not t.check_orientation
    env = TeacherEnv(cfg)
    tool = env.scene.plant.GetFrameByName("panda_tool")
    for seed in range(8):
        _, info = env.reset(seed=seed)
        hand = tool.CalcPoseInWorld(env.plant_context).translation()[:2]
        p_obj = env.episode.initial_object_pose[:2]
        p_goal = env.episode.goal_pose[:2]
        away, push = p_obj - hand, p_goal - p_obj
        distance = np.linalg.norm(away)
        assert g.object_distance_to_hand[0] - 1e-9 <= distance <= g.object_distance_to_hand[1] + 1e-9
        assert g.distance[0] - 1e-9 <= np.linalg.norm(push) <= g.distance[1] + 1e-9
        angle = np.arccos(away @ push / np.linalg.norm(away) / np.linalg.norm(push))
        assert angle <= g.heading_spread + 1e-9
        assert t.goal_x[0] <= p_goal[0] <= t.goal_x[1] and t.goal_y[0] <= p_goal[1] <= t.goal_y[1]
        assert info["status"]["orientation_error"] < 1e-6  # the goal keeps the start yaw


def test_push_turn_task_turns_the_goal_and_checks_orientation():
    """The orientation benchmark: the push task's goals turned by up to +-max_yaw, with the
    orientation part of success (TaskReward.status, tested on its own elsewhere)."""
    cfg = _task("push_turn")
    t, g = cfg.task, cfg.task.goal
    assert isinstance(g, PushFromHandGoal) and t.check_orientation and g.max_yaw > 0
    assert t.success_orientation < g.max_yaw  # some goals need a turn
    env = TeacherEnv(cfg)
    errors = []
    for seed in range(8):
        _, info = env.reset(seed=seed)
        errors.append(info["status"]["orientation_error"])
        assert info["status"]["success"] == 0.0
    # Every goal yaw within the range, and some beyond the tolerance (a straight push fails).
    assert max(errors) <= g.max_yaw + 1e-6 and max(errors) > t.success_orientation


def test_reset_names_the_task_and_ranges_when_no_goal_fits():
    cfg = _task("push")
    cfg.task.goal_x, cfg.task.goal_y = [0.5, 0.6], [0.5, 0.6]  # off the table: never reachable
    with pytest.raises(InputError, match=r"goal_x"):  # refused by the config's own check
        TeacherEnv(cfg)
    # Every range valid on its own, but no start puts the object that far from the hand on the
    # table: the sampler names the task and the ranges when the first reset finds no pair.
    cfg = _task("push")
    cfg.task.goal.object_distance_to_hand = [0.5, 0.6]
    env = TeacherEnv(cfg)
    with pytest.raises(InputError, match=r"task 'push'.*object_distance_to_hand \[0\.5, 0\.6\]"):
        env.reset(seed=0)


def test_a_failed_step_terminates_the_episode_with_a_valid_observation(env):
    """A diverging state (a huge velocity: the solver fails or leaves non-finite numbers) must end the episode as terminated:
    a truncated one would be bootstrapped from the value of a meaningless observation."""
    env.reset(seed=3)
    env.step(np.zeros(20))
    v = np.full(env.scene.plant.num_velocities(env.scene.object_instance), 1e300)
    env.scene.plant.SetVelocities(env.plant_context, env.scene.object_instance, v)
    obs, reward, terminated, truncated, info = env.step(np.zeros(20))
    assert terminated and not truncated and "sim_error" in info
    assert reward == 0.0 and env.observation_space.contains(obs)
    assert all(np.isfinite(o).all() for o in obs.values())
    obs, _ = env.reset(seed=3)  # the env is usable again after a reset
    assert all(np.isfinite(o).all() for o in obs.values())


def _torque_noise(env, steps=3, seed=None) -> np.ndarray:
    """The unit torque-noise samples the controller reads over the first `steps` steps."""
    env.reset(seed=seed)
    source = env.diagram.GetSubsystemByName("torque_noise")
    samples = []
    for _ in range(steps):
        env.step(np.zeros(20))
        samples.append(source.get_output_port().Eval(source.GetMyContextFromRoot(env.context)))
    return np.array(samples)


def test_torque_noise_is_fresh_every_episode_and_reproducible_from_the_seed():
    cfg = TeacherDiagramConfig()
    cfg.randomization.torque_noise_std = 0.03
    env = TeacherEnv(cfg)
    first = _torque_noise(env, seed=0)
    assert not np.allclose(_torque_noise(env), first)  # the next episode draws new noise
    other_cfg = TeacherDiagramConfig()
    other_cfg.randomization.torque_noise_std, other_cfg.seed = 0.03, 1
    assert not np.allclose(_torque_noise(TeacherEnv(other_cfg)), _torque_noise(TeacherEnv(cfg)))
    # A second env built with the same seed replays the same noise (Drake's own default seeds
    # differ per RandomSource instance, so this holds only if reset reseeds from the env's RNG).
    np.testing.assert_array_equal(_torque_noise(TeacherEnv(cfg), seed=0), first)


def test_object_radius_rescales_only_when_given_and_checks_its_range():
    env = TeacherEnv()
    env.reset(seed=0)
    assert env.episode.physics.scale == 1.0  # default: the object's own size
    cfg = load_config(TeacherDiagramConfig, text="randomization: {object_radius: [0.03, 0.03]}")
    env = TeacherEnv(cfg)
    env.reset(seed=0)
    assert np.isclose(env.episode.physics.scale * env.scene.object_spec.radius, 0.03)
    for bad in ("[0.0, 0.0]", "[0.05, 0.03]", "[0.03]"):
        cfg = load_config(TeacherDiagramConfig, text=f"randomization: {{object_radius: {bad}}}")
        with pytest.raises(InputError, match="randomization.object_radius"):
            TeacherEnv(cfg).reset(seed=0)
