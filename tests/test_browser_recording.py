"""A recorded episode opened in a real browser (issue 64): Debian's Chromium, headless, loads the
Meshcat HTML that `evaluate --record` writes and builds its scene: the object, the goal's
translucent red copy and the hand's path are in it, visible, and drawn. `make test` installs
Chromium (Makefile: system-deps); where it is missing the test says so and skips."""

import numpy as np
import pytest
from pydrake.geometry import Meshcat

from corn_drake.config.plumbing.diagram_files import load_teacher_config
from corn_drake.evaluation.episodes import run_episode
from corn_drake.rl.envs.teacher_env import TeacherEnv
from corn_drake.rl.scripted import ScriptedPushAgent
from corn_drake.viz.meshcat import EPISODE_PATH
from tests.recordings import chromium, scene_in_browser, screenshot_in_browser

STEPS = 8

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(chromium() is None,
                                 reason="no Chromium here (`make test` installs Debian's)")]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("recording")
    env = TeacherEnv(load_teacher_config("push"), meshcat=Meshcat())
    result = run_episode(env, ScriptedPushAgent(env.cfg.controller), seed=3, max_steps=STEPS,
                         record_path=folder / "episode.html")
    return result


def test_the_browser_builds_the_object_the_goal_copy_and_the_hands_path(recorded, tmp_path):
    scene = scene_in_browser(recorded.recording, tmp_path)
    shown = {o["path"].strip("/"): o for o in scene["objects"] if o["shown"]}
    episode = EPISODE_PATH.strip("/")
    objects = [p for p in shown if "/visualizer/object/" in p]
    goal = [p for p in shown if p.startswith(f"Scene/{episode}/goal/")]
    assert objects and all(shown[p]["vertices"] > 0 for p in objects), sorted(shown)
    assert goal and all(shown[p]["kind"] == "Mesh" for p in goal), sorted(shown)
    hand_path = shown.get(f"Scene/{episode}/hand_path")
    assert hand_path is not None and hand_path["kind"] == "Line", sorted(shown)
    assert hand_path["vertices"] == recorded.steps + 1  # one point per policy period
    assert scene["drawn"] > 0  # the renderer drew triangles, not an empty canvas


def test_the_goal_copy_is_drawn_in_its_red(recorded, tmp_path):
    image = screenshot_in_browser(recorded.recording, tmp_path).astype(int)
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    red = (r > 150) & (g < 120) & (b < 120)
    # The recording frames the push (viz/meshcat.show_goal): the goal copy fills a visible part
    # of an 800 x 600 view, not a stray pixel; the table and the sky are not red.
    assert red.sum() > 500, f"{red.sum()} red pixels"
    assert image.std() > 10  # a drawn scene, not a blank page
