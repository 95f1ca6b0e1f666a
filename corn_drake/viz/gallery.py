"""Gallery stills: a teacher's episode rendered headless by a Drake camera, the object's cloud
painted by the policy's attention (the paper's attention figure, as PNG).

Each still is one policy step: the scene rendered by an RgbdSensor (RenderEngineVtk, headless
EGL) from a fixed eye, and on top of it the observation's cloud (world frame, the points the
policy read) projected through the same camera and coloured viridis by the step's point scores
(nn/attention.py; viz/attention_view.py uses the same colours in Meshcat), and the goal
position as a red dot. Only points the
depth image shows are painted: a point behind the object's own surface or behind the hand
stays hidden, so the colours sit on what the camera sees.

The episode itself is run in evaluation/stills.py (viz runs no env); the render diagram here
is a second copy of the scene whose positions are set from the env's plant.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np


# The eye looks at the midpoint of the object's start and goal from the side of the push (the
# hand pushes along start -> goal, so from behind or in front it would hide the object), on
# the side away from the robot's base (which stands at -x), EYE_SIDE out and EYE_UP above.
EYE_SIDE, EYE_UP = 0.5, 0.14
WIDTH, HEIGHT, FOV_Y_DEG = 640, 480, 45.0
GOAL_COLOUR = np.array([230, 30, 30], np.uint8)
POINT_RADIUS_PX = 3
DEPTH_SLACK_M = 0.01  # a point within this of the rendered depth counts as visible


@dataclasses.dataclass
class Still:
    step: int
    image: np.ndarray  # (H, W, 3) uint8, painted
    painted_points: int  # cloud points visible and painted


class StillCamera:
    """A render-only copy of the scene (robot, table, object) with one fixed RgbdSensor."""

    def __init__(self, scene_cfg, spec, eye: np.ndarray, target: np.ndarray):
        from pydrake.systems.framework import DiagramBuilder
        from pydrake.systems.sensors import CameraConfig, RgbdSensor

        from corn_drake.scene.builder import build_scene
        from corn_drake.systems.cameras import add_renderer, look_at

        builder = DiagramBuilder()
        self.scene = build_scene(builder, scene_cfg, spec)
        camera = CameraConfig(width=WIDTH, height=HEIGHT, focal=CameraConfig.FovDegrees(y=FOV_Y_DEG),
                              clipping_near=0.01, clipping_far=4.0, z_near=0.01, z_far=4.0,
                              renderer_name="gallery_vtk", renderer_class="RenderEngineVtk",
                              name="gallery_camera", rgb=True, depth=True)
        add_renderer(self.scene.scene_graph, camera)
        color, depth = camera.MakeCameras()
        self.X_WC = look_at(np.asarray(eye, float), np.asarray(target, float))
        self.sensor = builder.AddSystem(RgbdSensor(self.scene.scene_graph.world_frame_id(),
                                                   self.X_WC, color, depth))
        builder.Connect(self.scene.scene_graph.get_query_output_port(),
                        self.sensor.query_object_input_port())
        self.intrinsics = depth.core().intrinsics()
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self._plant_context = self.scene.plant.GetMyContextFromRoot(self.context)

    def render(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(RGB (H, W, 3) uint8, depth (H, W) metres) with the plant at `positions`."""
        self.scene.plant.SetPositions(self._plant_context, positions)
        ctx = self.sensor.GetMyContextFromRoot(self.context)
        rgba = self.sensor.color_image_output_port().Eval(ctx).data
        depth = self.sensor.depth_image_32F_output_port().Eval(ctx).data[..., 0]
        return np.array(rgba[..., :3], dtype=np.uint8), np.array(depth, dtype=float)

    def project(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(pixel (N, 2) float u, v; depth along the optical axis (N,)) of world points."""
        p_C = self.X_WC.inverse().multiply(np.asarray(points_world, float).T).T
        z = p_C[:, 2]
        k = self.intrinsics
        with np.errstate(divide="ignore", invalid="ignore"):
            u = k.focal_x() * p_C[:, 0] / z + k.center_x()
            v = k.focal_y() * p_C[:, 1] / z + k.center_y()
        return np.stack([u, v], axis=1), z


def paint(image: np.ndarray, depth: np.ndarray, pixels: np.ndarray, z: np.ndarray,
          colours: np.ndarray, radius: int = POINT_RADIUS_PX) -> tuple[np.ndarray, int]:
    """`image` with a disc of each visible point's colour (nearest points drawn last); a point
    is visible when it is in front of the camera, inside the image, and no farther than the
    rendered depth at its pixel (+ DEPTH_SLACK_M). Returns (painted copy, points painted)."""
    out = image.copy()
    h, w = depth.shape
    ui, vi = np.round(pixels[:, 0]), np.round(pixels[:, 1])
    inside = (z > 0) & (ui >= 0) & (ui < w) & (vi >= 0) & (vi < h) & np.isfinite(ui + vi)
    idx = np.flatnonzero(inside)
    ui, vi = ui[idx].astype(int), vi[idx].astype(int)
    visible = z[idx] <= depth[vi, ui] + DEPTH_SLACK_M
    idx, ui, vi = idx[visible], ui[visible], vi[visible]
    dy, dx = np.mgrid[-radius:radius + 1, -radius:radius + 1]
    disc = dx ** 2 + dy ** 2 <= radius ** 2
    for j in np.argsort(-z[idx]):  # far first, near on top
        y0, x0 = vi[j], ui[j]
        ys, xs = y0 + dy[disc], x0 + dx[disc]
        keep = (ys >= 0) & (ys < h) & (xs >= 0) & (xs < w)
        out[ys[keep], xs[keep]] = colours[idx[j]]
    return out, len(idx)




def side_view(start: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(eye, target) of the camera for a push from `start` to `goal` (world positions)."""
    target = (np.asarray(start, float) + np.asarray(goal, float)) / 2
    d = np.asarray(goal, float)[:2] - np.asarray(start, float)[:2]
    d = d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-6 else np.array([1.0, 0.0])
    side = np.array([-d[1], d[0]])
    if side[0] < 0 or (side[0] == 0 and side[1] < 0):  # away from the robot's base at -x
        side = -side
    return target + np.array([*(EYE_SIDE * side), EYE_UP]), target


def pick_steps(wanted: str, n: int) -> list[int]:
    names = {"start": 0, "middle": (n - 1) // 2, "end": n - 1}
    picks = []
    for word in wanted.split(","):
        word = word.strip()
        k = names[word] if word in names else int(word)
        if not 0 <= k < n:
            raise ValueError(f"step {word!r} is outside the episode's {n} observations")
        picks.append(k)
    return picks


def save_png(image: np.ndarray, path: str | Path) -> Path:
    """`image` as a PNG, written atomically."""
    from PIL import Image

    from corn_drake.storage.atomic_files import atomic_path

    path = Path(path)
    with atomic_path(path) as tmp:
        Image.fromarray(image).save(tmp, format="PNG")
    return path
