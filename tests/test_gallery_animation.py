"""The gallery's goal copy and its animation, rendered by the gallery's own camera on the tiny
fixture library (no policy, no episode: frames made by moving the object toward its goal)."""

import numpy as np
import pytest

from corn_drake.systems.perception.cameras import rendering_available
from corn_drake.viz.gallery import GOAL_COLOUR, animation_picks, goal_ghost, save_gif
from tests.fixtures import write_loadable_library


def _reddish(image: np.ndarray) -> np.ndarray:
    r, g, b = (image[..., i].astype(int) for i in range(3))
    return (r > 90) & (r > 2 * g) & (r > 2 * b)


def test_the_goal_copy_is_blended_in_front_and_hidden_behind():
    rgb = np.full((6, 8, 3), 100, np.uint8)
    depth = np.full((6, 8), 1.0)
    depth[:, 6:] = 0.2  # something (the object, the hand) stands in front on the right
    goal_rgb = np.full((6, 8, 3), 200, np.uint8)
    goal_depth = np.full((6, 8), np.inf)
    goal_depth[1:5, 1:8] = 0.5  # the goal copy's silhouette
    empty = np.full((6, 8), np.inf)
    out = goal_ghost(rgb, depth, goal_rgb, goal_depth, empty)
    assert tuple(out[0, 0]) == (100, 100, 100)  # outside the silhouette: untouched
    assert tuple(out[1, 3]) == tuple(GOAL_COLOUR)  # its outline: solid
    inside = out[2, 3].astype(int)
    assert inside[0] > 100 and inside[1] < 100  # inside: the scene tinted red, not replaced
    assert tuple(out[2, 7]) == (100, 100, 100)  # behind the nearer surface: hidden


def test_animation_picks_keep_the_first_and_last_step():
    assert animation_picks(5) == [0, 1, 2, 3, 4]
    assert animation_picks(40, 3) == [0, 19, 39]
    assert animation_picks(2, 5) == [0, 1]


def test_an_animation_of_the_object_moving_to_its_goal_is_a_gif_of_changing_frames(tmp_path):
    ok, reason = rendering_available()
    if not ok:
        pytest.skip(reason)
    from PIL import Image, ImageSequence

    from corn_drake.assets.library import list_objects, load_object_spec
    from corn_drake.config.plumbing.diagram_files import load_teacher_config
    from corn_drake.viz.gallery import StillCamera, side_view

    library = write_loadable_library(tmp_path / "lib", 1)
    spec = load_object_spec(library, list_objects(library)[0])
    start = np.array(spec.stable_poses[0], float)
    start[:2] = [-0.08, -0.12]
    goal = start.copy()
    goal[:2] = [0.06, 0.1]
    camera = StillCamera(load_teacher_config().scene, spec, *side_view(start, goal, spec.radius),
                         width=96, height=72)
    positions = camera.scene.plant.GetPositions(camera._plant_context).copy()
    images = []
    for t in (0.0, 0.5, 1.0):
        pose = start.copy()
        pose[:3] = (1 - t) * start[:3] + t * goal[:3]
        camera.render(positions, pose)  # leaves the object there for render_with_goal
        image, _ = camera.render_with_goal(
            camera.scene.plant.GetPositions(camera._plant_context), goal)
        images.append(image)
    path = save_gif(images, tmp_path / "push.gif")
    assert path.read_bytes()[:6] in (b"GIF87a", b"GIF89a")
    with Image.open(path) as gif:
        frames = [np.array(f.convert("RGB")) for f in ImageSequence.Iterator(gif)]
    assert len(frames) == 3 and frames[0].shape == (72, 96, 3)
    # The picture changes as the object moves, and the goal copy is in it.
    for a, b in zip(frames, frames[1:]):
        assert (np.abs(a.astype(int) - b.astype(int)).sum(axis=-1) > 30).sum() > 20
    assert _reddish(frames[0]).sum() > 20
    with pytest.raises(ValueError, match="at least 2"):
        save_gif(images[:1], tmp_path / "one.gif")



@pytest.mark.parametrize("flags, needle", [
    (["--animate", "--frames", "1"], "--frames 1"),
    (["--animate", "--frames", "-2"], "--frames -2"),
    (["--animate", "--frame-height", "20"], "--frame-height 20"),
    (["--frames", "5"], "--animate")])
def test_gallery_refuses_an_animation_it_cannot_make_before_writing(tmp_path, capsys, flags,
                                                                    needle):
    from corn_drake.cli import main
    from tests.fixtures import one_error_line

    out = tmp_path / "g"
    assert main(["gallery", "--run", str(tmp_path / "nowhere"), "--objects", str(tmp_path),
                 "--out", str(out), *flags]) == 2
    one_error_line(capsys, needle)
    assert not out.exists()
