"""Meshcat helpers: a visualizer on a diagram and episodes saved as standalone HTML."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role

from corn_drake.storage.atomic_files import write_text


def add_meshcat_visualizer(builder, scene_graph, meshcat: Meshcat, publish_period: float = 0.05):
    params = MeshcatVisualizerParams(role=Role.kIllustration, publish_period=publish_period)
    return MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, params)


def save_recording(meshcat: Meshcat, path: str | Path) -> Path:
    """Publishes the recording and writes Meshcat's standalone HTML (opens in any browser)."""
    meshcat.PublishRecording()
    path = Path(path)
    write_text(path, meshcat.StaticHtml())
    return path


# What an episode's view adds to the scene (issue 55: pictures that show the task): the object's
# goal as a translucent red copy, the hand's path as a line, and a camera framed on the push.
# They live under EPISODE_PATH, cleared at each episode's start, so one Meshcat serves many.
EPISODE_PATH = "/episode"
GOAL_RGBA = (0.9, 0.12, 0.12, 0.35)  # the gallery's goal red, see-through
PATH_RGBA = (0.85, 0.1, 0.85, 1.0)  # magenta, the colour of the primitive view's contact point
PATH_WIDTH = 3.0


def show_goal(meshcat: Meshcat, spec, goal_pose, start_pose) -> None:
    """Draws `spec`'s shapes (scene.builder.object_shapes: what the object collides as) at
    `goal_pose` ([p, q_wxyz]) in translucent red, and points the camera at the push from its
    side (viz/gallery.side_view: the stills' framing) so the start, goal and object fill it."""
    from pydrake.common.eigen_geometry import Quaternion
    from pydrake.geometry import Rgba
    from pydrake.math import RigidTransform

    from corn_drake.scene.builder import object_shapes
    from corn_drake.viz.gallery import side_view

    goal = np.asarray(goal_pose, float)
    meshcat.Delete(EPISODE_PATH)
    for i, shape in enumerate(object_shapes(spec)):
        meshcat.SetObject(f"{EPISODE_PATH}/goal/{i}", shape, Rgba(*GOAL_RGBA))
    q = goal[3:7] / np.linalg.norm(goal[3:7])
    meshcat.SetTransform(f"{EPISODE_PATH}/goal", RigidTransform(Quaternion(q), goal[:3]))
    eye, target = side_view(np.asarray(start_pose, float)[:3], goal[:3], spec.radius)
    meshcat.SetCameraPose(eye, target)


def show_path(meshcat: Meshcat, points) -> None:
    """The hand's path: a line through `points` ((N, 3) tool positions, one per policy
    period)."""
    from pydrake.geometry import Rgba

    points = np.asarray(points, float)
    if len(points) >= 2:
        meshcat.SetLine(f"{EPISODE_PATH}/hand_path", points.T, PATH_WIDTH, Rgba(*PATH_RGBA))
