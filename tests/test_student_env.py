"""StudentEnv: both observation sets of one state, tracking info, seeding, bad input, batching."""

import numpy as np
import pytest

from corn_drake.contract import (ACTION_DIM, OBS_KEYS, ROBOT_STATE_DIM, STUDENT_OBS_KEYS,
                                 observation_shapes)
from corn_drake.config.plumbing.diagram_files import load_student_config
from corn_drake.errors import InputError
from corn_drake.rl.envs.teacher_env import TeacherEnv
from corn_drake.rl.envs.student_env import StudentEnv
from corn_drake.rl.envs.vec_env import EnvBatch, EnvFactory, concat_obs, stack_obs

# Observation keys the student sees without perception or noise: equal to the teacher's.
EXACT_KEYS = ("hand_state", "robot_state", "previous_action")


def _config():
    """The base student diagram without joint-torque noise, so the physics matches the teacher
    diagram's for the same seed whatever order the two diagrams reseed their RandomSources in
    (the student diagram has more of them). The student's cloud and goal noise stay on."""
    cfg = load_student_config()
    cfg.teacher.randomization.torque_noise_std = 0.0
    return cfg


@pytest.fixture(scope="module")
def env():
    return StudentEnv(_config())


def _actions(n, seed=0):
    return np.random.default_rng(seed).uniform(-1, 1, (n, ACTION_DIM))


def test_reset_and_step_return_both_observation_sets(env):
    n_student = env.cfg.segmentation.num_points
    n_teacher = env.teacher_cfg.scene.object.cloud_points
    obs, info = env.reset(seed=0)
    for o in (obs, env.step(_actions(1)[0])[0]):
        assert set(o) == {"student", "teacher"}
        assert tuple(o["student"]) == STUDENT_OBS_KEYS and tuple(o["teacher"]) == OBS_KEYS
        assert {k: v.shape for k, v in o["student"].items()} == {
            k: observation_shapes(n_student)[k] for k in STUDENT_OBS_KEYS}
        assert {k: v.shape for k, v in o["teacher"].items()} == observation_shapes(n_teacher)
        assert env.observation_space.contains(o)
        assert all(np.isfinite(v).all() for d in o.values() for v in d.values())
    # The tracker starts from the true pose: no error at the episode's start.
    assert info["tracking"]["translation_error_m"] < 1e-9
    assert info["tracking"]["segmented_points"] > 0
    assert set(info["status"]) >= {"success", "out_of_workspace"}


def test_object_poses_and_depth_images_describe_the_current_state(env):
    env.reset(seed=1)
    X_est, X_true = env.object_poses()
    # The tracker starts from the true pose; the truth is the plant's object pose.
    np.testing.assert_allclose(X_est, X_true, atol=1e-9)
    np.testing.assert_allclose(X_true[:3, 3], env.episode.initial_object_pose[:3],
                               atol=1e-3)
    images = env.depth_images()
    camera = env.cfg.cameras.camera
    assert len(images) == len(env.cfg.cameras.eyes)
    assert all(im.shape == (camera.height, camera.width) for im in images)
    # Every eye sees the table (about half of each image here); past its edge nothing returns.
    assert all(0.2 < np.isfinite(im).mean() < 1 for im in images)
    assert all(np.nanmin(im) >= camera.z_near for im in images)
    for _ in range(3):
        env.step(np.zeros(ACTION_DIM))
    X_est, X_true = env.object_poses()
    assert env.tracking_error()["translation_error_m"] == pytest.approx(
        np.linalg.norm(X_est[:3, 3] - X_true[:3, 3]))


def test_teacher_observation_matches_teacher_env_and_student_sees_same_state(env):
    teacher_env = TeacherEnv(env.cfg.teacher, spec=env.scene.object_spec)
    s_obs, s_info = env.reset(seed=3)
    t_obs, t_info = teacher_env.reset(seed=3)
    np.testing.assert_array_equal(env.episode.initial_object_pose,
                                  teacher_env.episode.initial_object_pose)
    for k, action in enumerate([None, *_actions(3, seed=1)]):
        if action is not None:
            s_obs, s_rew, *_, s_info = env.step(action)
            t_obs, t_rew, *_, t_info = teacher_env.step(action)
            assert s_rew == pytest.approx(t_rew, abs=1e-9), k
        for key in OBS_KEYS:
            np.testing.assert_allclose(s_obs["teacher"][key], t_obs[key], atol=1e-6,
                                       err_msg=f"step {k} teacher key {key}")
        for key in EXACT_KEYS:
            np.testing.assert_allclose(s_obs["student"][key], t_obs[key], atol=1e-6,
                                       err_msg=f"step {k} student key {key}")
        # The goal is relative to the *tracked* pose, with 2 mm noise: close, not equal.
        np.testing.assert_allclose(s_obs["student"]["goal"][:3], t_obs["goal"][:3], atol=0.02)
        # The student's cloud is a partial view of the same object: near its centre.
        centre = t_obs["object_keypoints"].reshape(-1, 3).mean(0)
        assert np.linalg.norm(s_obs["student"]["cloud"].mean(0) - centre) < 0.05
        assert s_info["tracking"]["translation_error_m"] < 0.01
    assert action is not None  # the loop stepped


def test_episodes_differ_and_a_seed_repeats(env):
    first, _ = env.reset(seed=11)
    pose = env.episode.initial_object_pose.copy()
    step = env.step(_actions(1)[0])[0]
    second, _ = env.reset()
    assert not np.allclose(env.episode.initial_object_pose, pose)
    assert not np.allclose(second["student"]["cloud"], first["student"]["cloud"])
    again, _ = env.reset(seed=11)
    again_step = env.step(_actions(1)[0])[0]
    for a, b in ((first, again), (step, again_step)):
        for part in ("student", "teacher"):  # the student's noise is reseeded with the episode
            for key in a[part]:
                np.testing.assert_array_equal(a[part][key], b[part][key], err_msg=f"{part}.{key}")


@pytest.mark.parametrize("action", [np.zeros(ACTION_DIM - 1), np.full(ACTION_DIM, np.nan)])
def test_bad_action_raises_before_the_simulator(env, action):
    env.reset(seed=0)
    t0 = env.context.get_time()
    x0 = env.scene.plant.GetPositionsAndVelocities(env.plant_context).copy()
    with pytest.raises(ValueError, match="action"):
        env.step(action)
    assert env.context.get_time() == t0
    np.testing.assert_array_equal(env.scene.plant.GetPositionsAndVelocities(env.plant_context), x0)


def test_perception_choice():
    with pytest.raises(InputError, match="perception"):
        StudentEnv(_config(), perception="oracle")
    gt = StudentEnv(_config(), perception="ground_truth")
    assert gt.perception == "ground_truth" and gt.cfg.segmentation.mode == "ground_truth"
    obs, info = gt.reset(seed=0)
    obs = gt.step(np.zeros(ACTION_DIM))[0]
    assert np.isfinite(obs["student"]["cloud"]).all()


def test_nested_observations_stack_and_concatenate():
    a = {"student": {"x": np.zeros(2)}, "teacher": {"y": np.ones((3, 1))}}
    b = {"student": {"x": np.ones(2)}, "teacher": {"y": np.zeros((3, 1))}}
    s = stack_obs([a, b])
    assert s["student"]["x"].shape == (2, 2) and s["teacher"]["y"].shape == (2, 3, 1)
    np.testing.assert_array_equal(s["student"]["x"][1], b["student"]["x"])
    c = concat_obs([s, stack_obs([a])])
    assert c["student"]["x"].shape == (3, 2)
    np.testing.assert_array_equal(c["teacher"]["y"][2], a["teacher"]["y"])


def test_env_batch_of_student_envs_steps_and_auto_resets():
    cfg = _config()
    cfg.teacher.task.episode_steps = 2
    batch = EnvBatch(EnvFactory(cfg, seed=5), 2)
    assert all(isinstance(e, StudentEnv) for e in batch.envs)
    obs = batch.reset()
    assert obs["student"]["cloud"].shape == (2, cfg.segmentation.num_points, 3)
    assert obs["teacher"]["object_keypoints"].shape[0] == 2
    # The two envs run different episodes.
    assert not np.allclose(obs["teacher"]["goal"][0], obs["teacher"]["goal"][1])
    batch.step(np.zeros((2, ACTION_DIM)))
    result = batch.step(np.zeros((2, ACTION_DIM)))
    assert result.truncated.all() and len(result.episode_stats) == 2
    assert set(result.final_obs) == {0, 1}
    assert set(result.final_obs[0]) == {"student", "teacher"}
    assert result.obs["student"]["robot_state"].shape == (2, ROBOT_STATE_DIM)
    # After the automatic reset the new episode starts with a zero previous action.
    assert np.all(result.obs["student"]["previous_action"] == 0)
    assert not np.all(result.final_obs[0]["student"]["previous_action"] == 0)


def test_solver_failure_ends_the_episode_with_zero_observations(env, monkeypatch):
    env.reset(seed=0)

    class FailingSimulator:  # pydrake's Simulator methods cannot be patched
        def AdvanceTo(self, t):
            raise RuntimeError("solver failed")

    monkeypatch.setattr(env, "simulator", FailingSimulator())
    obs, reward, terminated, truncated, info = env.step(np.zeros(ACTION_DIM))
    assert terminated and not truncated and reward == 0.0
    assert info["sim_error"] == "solver failed" and "tracking" not in info
    assert env.observation_space.contains(obs)
    assert all(not v.any() for part in obs.values() for v in part.values())


@pytest.mark.slow
def test_ray_workers_run_student_envs_as_an_in_process_batch():
    """DAgger's rollouts on Ray workers: a worker renders, segments and tracks in its own
    process, and returns both observation sets of the same episodes as an in-process batch
    (a worker's envs take their global index, so the seeds match)."""
    ray = pytest.importorskip("ray")
    from corn_drake.rl.workers.ray_workers import RayEnvBatch, init_ray

    cfg = _config()
    cfg.teacher.task.episode_steps = 2
    factory = EnvFactory(cfg, seed=7)
    actions = _actions(3 * 2, seed=2).reshape(3, 2, ACTION_DIM)

    def run(batch):
        steps = [batch.reset()] + [batch.step(a) for a in actions]
        stats = [s for r in steps[1:] for s in r.episode_stats]
        return [steps[0]] + [r.obs for r in steps[1:]], stats

    local, local_stats = run(EnvBatch(factory, 2))
    init_ray(num_cpus=2)
    try:
        remote, remote_stats = run(RayEnvBatch(factory, num_workers=1, envs_per_worker=2))
    finally:
        ray.shutdown()
    assert len(remote_stats) == len(local_stats) == 2  # both episodes ended after 2 steps
    for key in ("success", "length", "object"):
        assert [s[key] for s in remote_stats] == [s[key] for s in local_stats]
    for got, want in zip(remote, local):
        for part in ("student", "teacher"):
            assert set(got[part]) == set(want[part])
            for key in want[part]:
                # Same physics and noise seeds; the ICP estimate may differ in the last bits.
                np.testing.assert_allclose(got[part][key], want[part][key], atol=1e-5,
                                           err_msg=f"{part}/{key}")
