"""What a recorded episode shows beside the scene (issue 55): the object's goal as a translucent
red copy at the episode's goal pose, the hand's path through the tool's positions, and a camera
framed on the push (viz/meshcat.show_goal / show_path). Read back from the HTML itself."""

import numpy as np
from pydrake.geometry import Meshcat

from corn_drake.config.plumbing.diagram_files import load_teacher_config
from corn_drake.evaluation.episodes import run_episode
from corn_drake.rl.envs.teacher_env import TeacherEnv
from corn_drake.rl.scripted import ScriptedPushAgent
from corn_drake.viz.meshcat import EPISODE_PATH, GOAL_RGBA
from tests.recordings import meshcat_messages

STEPS = 6


def test_a_recording_shows_the_goal_the_hands_path_and_frames_the_push(tmp_path):
    env = TeacherEnv(load_teacher_config("push"), meshcat=Meshcat())
    result = run_episode(env, ScriptedPushAgent(env.cfg.controller), seed=3, max_steps=STEPS,
                         record_path=tmp_path / "episode.html")
    messages = meshcat_messages(result.recording.read_text())
    by_path = {}
    for msg in messages:
        by_path.setdefault((msg["type"], msg.get("path")), []).append(msg)

    goal_shapes = [m for (kind, path), ms in by_path.items() for m in ms
                   if kind == "set_object" and path.startswith(f"{EPISODE_PATH}/goal/")]
    assert goal_shapes, "no goal copy in the recording"
    for msg in goal_shapes:  # translucent, the goal's red
        material = msg["object"]["materials"][0]
        assert material["transparent"] and abs(material["opacity"] - GOAL_RGBA[3]) < 1e-6

    # The goal copy stands where the episode's goal is (a column-major 4x4 transform).
    (goal_transform,) = by_path[("set_transform", f"{EPISODE_PATH}/goal")]
    X = np.asarray(goal_transform["matrix"], float).reshape(4, 4).T
    np.testing.assert_allclose(X[:3, 3], result.goal_pose[:3], atol=1e-9)

    # One point per policy period after the start, through the tool's positions.
    (path_msg,) = [m for (kind, path), ms in by_path.items() for m in ms
                   if kind == "set_object" and path == f"{EPISODE_PATH}/hand_path"]
    array = path_msg["object"]["geometries"][0]["data"]["attributes"]["position"]["array"]
    # A Float32Array travels as msgpack extension type 0x17 (little-endian float32 bytes).
    assert array.code == 0x17
    positions = np.frombuffer(array.data, "<f4").reshape(-1, 3)
    assert len(positions) == result.steps + 1
    np.testing.assert_allclose(positions[-1], env.tool_position(), atol=1e-5)
    assert np.linalg.norm(positions[-1] - positions[0]) > 1e-3  # the hand moved

    # The camera looks at the push, not at Meshcat's default origin view.
    cameras = [m for (kind, path), ms in by_path.items() for m in ms
               if path and path.startswith("/Cameras/default")]
    assert cameras, "the camera was not placed"
