"""Gallery stills: a teacher's episode rendered headless by a Drake camera, the object's cloud
painted by the policy's attention (the paper's attention figure, as PNG).

Each still is one policy step: the scene rendered by an RgbdSensor (RenderEngineVtk, headless
EGL) from a fixed eye, and on top of it the observation's cloud (world frame, the points the
policy read) projected through the same camera and coloured viridis by the step's point scores
(nn/attention.py; viz/attention_view.py uses the same colours in Meshcat). The goal is a
translucent red copy of the object at its goal pose (goal_ghost), drawn where nothing stands in
front of it. Only points the depth image shows are painted: a point behind the object's own
surface or behind the hand stays hidden, so the colours sit on what the camera sees.

`corn-drake gallery --animate` renders every step of the same episode through the same camera
(smaller) and saves them as a GIF (save_gif).

The episode itself is run in evaluation/stills.py (viz runs no env); the render diagram here
is a second copy of the scene whose positions are set from the env's plant.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np


# The eye looks at the midpoint of the object's start and goal from the side of the push (the
# hand pushes along start -> goal, so from behind or in front it would hide the object), on
# the side away from the robot's base (which stands at -x, so the arm is behind the object, not
# in front of it), EYE_ELEVATION_DEG above the table so the table top, not its front face,
# fills the picture, and far enough that the start, the goal and the object around both fit:
# FRAME_SCALE times their span (at a 45 degree vertical field of view a span fills about 3/4 of
# the width at 1.1x), never nearer than MIN_EYE_DISTANCE.
EYE_ELEVATION_DEG, MIN_EYE_DISTANCE, FRAME_SCALE, FRAME_MARGIN = 35.0, 0.4, 1.1, 0.12
WIDTH, HEIGHT, FOV_Y_DEG = 640, 480, 45.0
GOAL_COLOUR = np.array([230, 30, 30], np.uint8)
GOAL_ALPHA = 0.6  # the goal copy's weight over what is behind it: both stay readable
POINT_RADIUS_PX = 3
DEPTH_SLACK_M = 0.01  # a point within this of the rendered depth counts as visible
AWAY_M = 50.0  # the object's height when it is moved out of the picture (past the far clip)


@dataclasses.dataclass
class Still:
    step: int
    image: np.ndarray  # (H, W, 3) uint8, painted
    painted_points: int  # cloud points visible and painted


class StillCamera:
    """A render-only copy of the scene (robot, table, object) with one fixed RgbdSensor."""

    def __init__(self, scene_cfg, spec, eye: np.ndarray, target: np.ndarray,
                 width: int = WIDTH, height: int = HEIGHT):
        from pydrake.systems.framework import DiagramBuilder
        from pydrake.systems.sensors import CameraConfig, RgbdSensor

        from corn_drake.scene.builder import build_scene
        from corn_drake.systems.perception.cameras import add_renderer, look_at

        builder = DiagramBuilder()
        self.scene = build_scene(builder, scene_cfg, spec)
        camera = CameraConfig(width=width, height=height, focal=CameraConfig.FovDegrees(y=FOV_Y_DEG),
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

    def render(self, positions: np.ndarray, object_pose: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
        """(RGB (H, W, 3) uint8, depth (H, W) metres) with the plant at `positions`, the object
        moved to `object_pose` ((7,) [p, q_wxyz]) when given."""
        from pydrake.common.eigen_geometry import Quaternion
        from pydrake.math import RigidTransform

        self.scene.plant.SetPositions(self._plant_context, positions)
        if object_pose is not None:
            pose = np.asarray(object_pose, float)
            q = pose[3:] / np.linalg.norm(pose[3:])
            self.scene.plant.SetFreeBodyPose(self._plant_context, self.scene.object_body,
                                             RigidTransform(Quaternion(q), pose[:3]))
        ctx = self.sensor.GetMyContextFromRoot(self.context)
        rgba = self.sensor.color_image_output_port().Eval(ctx).data
        depth = self.sensor.depth_image_32F_output_port().Eval(ctx).data[..., 0]
        return np.array(rgba[..., :3], dtype=np.uint8), np.array(depth, dtype=float)

    def render_with_goal(self, positions: np.ndarray, goal_pose: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
        """render(positions) with the goal copy of the object drawn in (goal_ghost). Two more
        renders find it: the object at its goal and the object away; where they differ is the
        goal copy's silhouette, already hidden wherever the robot stands in front of it."""
        rgb, depth = self.render(positions)
        goal_rgb, goal_depth = self.render(positions, goal_pose)
        away = np.array([0.0, 0.0, -AWAY_M, 1.0, 0.0, 0.0, 0.0])
        _, empty_depth = self.render(positions, away)
        return goal_ghost(rgb, depth, goal_rgb, goal_depth, empty_depth), depth

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




def goal_ghost(rgb: np.ndarray, depth: np.ndarray, goal_rgb: np.ndarray,
               goal_depth: np.ndarray, empty_depth: np.ndarray) -> np.ndarray:
    """`rgb` (the scene as it is, `depth` its depth) with a translucent red copy of the object
    at its goal: `goal_rgb` / `goal_depth` render the scene with the object at its goal,
    `empty_depth` with the object away. The copy covers the pixels where the goal render is
    nearer than the empty one; it is blended in (GOAL_ALPHA, shaded by the goal render's
    brightness so its faces stay apart) where it is not behind what `rgb` shows (the object
    itself, near or at its goal, stays on top), and its outline is drawn solid there."""
    silhouette = goal_depth < empty_depth - DEPTH_SLACK_M / 10
    shown = silhouette & (goal_depth <= depth + DEPTH_SLACK_M)
    inner = silhouette.copy()  # the silhouette shrunk by one pixel: what is left is its outline
    inner[1:] &= silhouette[:-1]
    inner[:-1] &= silhouette[1:]
    inner[:, 1:] &= silhouette[:, :-1]
    inner[:, :-1] &= silhouette[:, 1:]
    out = rgb.astype(float)
    shade = 0.5 + 0.5 * goal_rgb.astype(float).mean(axis=-1, keepdims=True) / 255.0
    tint = np.clip(GOAL_COLOUR * shade, 0, 255)
    out = np.where(shown[..., None], (1 - GOAL_ALPHA) * out + GOAL_ALPHA * tint, out)
    out[shown & ~inner] = GOAL_COLOUR
    return out.round().astype(np.uint8)


def side_view(start: np.ndarray, goal: np.ndarray, radius: float = 0.1
              ) -> tuple[np.ndarray, np.ndarray]:
    """(eye, target) of the camera for a push from `start` to `goal` (world positions) of an
    object of `radius` (m)."""
    start, goal = np.asarray(start, float)[:3], np.asarray(goal, float)[:3]
    target = (start + goal) / 2
    d = goal[:2] - start[:2]
    span = np.linalg.norm(d) + 2 * radius + FRAME_MARGIN
    d = d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-6 else np.array([1.0, 0.0])
    side = np.array([-d[1], d[0]])
    if side[0] < 0 or (side[0] == 0 and side[1] < 0):  # away from the robot's base at -x
        side = -side
    distance = max(MIN_EYE_DISTANCE, FRAME_SCALE * span)
    elevation = np.radians(EYE_ELEVATION_DEG)
    eye = target + distance * np.array([*(np.cos(elevation) * side), np.sin(elevation)])
    return eye, target


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


def animation_picks(n: int, frames: int = 0) -> list[int]:
    """Which of an episode's `n` observations an animation shows: all when `frames` is 0, else
    `frames` of them evenly spaced, the first and the last always among them."""
    if frames <= 0 or frames >= n:
        return list(range(n))
    return sorted({int(k) for k in np.linspace(0, n - 1, frames)})  # floor: as pick_steps' middle


def save_gif(images: list[np.ndarray], path: str | Path, frame_ms: int = 250,
             hold_last_ms: int = 1500) -> Path:
    """`images` as a looping GIF, each frame `frame_ms` and the last `hold_last_ms` (so the
    outcome is seen before it starts again), written atomically."""
    from PIL import Image

    from corn_drake.storage.atomic_files import atomic_path

    if len(images) < 2:
        raise ValueError(f"an animation needs at least 2 frames, got {len(images)}")
    path = Path(path)
    # One adaptive palette per frame: the scene's greys and the goal's red both keep their tones.
    frames = [Image.fromarray(image).convert("P", palette=Image.Palette.ADAPTIVE, colors=128)
              for image in images]
    durations = [frame_ms] * (len(frames) - 1) + [hold_last_ms]
    with atomic_path(path) as tmp:
        frames[0].save(tmp, format="GIF", save_all=True, append_images=frames[1:],
                       duration=durations, loop=0, optimize=False)
    return path


def save_png(image: np.ndarray, path: str | Path) -> Path:
    """`image` as a PNG, written atomically."""
    from PIL import Image

    from corn_drake.storage.atomic_files import atomic_path

    path = Path(path)
    with atomic_path(path) as tmp:
        Image.fromarray(image).save(tmp, format="PNG")
    return path
