"""Low side pushes (systems/control/low_push.py, PrimitiveConfig.push_height and finger_tilt_deg): the aim
point drops toward the table on side faces only, as far as the cloud leaves room for the
fingers; the leaning hand's rotation; and in the real diagram a push on a tall box tips it with
vertical fingers (the palm meets it first) and slides it pushed low with leaning fingers."""

from __future__ import annotations

import numpy as np
import pytest

from corn_drake.config.primitive import PrimitiveConfig
from corn_drake.scene.objects import TABLE_TOP_Z
from corn_drake.systems.control.low_push import FINGER_COLUMN_RADIUS, FINGER_DEPTH, push_contact

LOW = PrimitiveConfig(push_height=0.02)


def _box_cloud(half: float, height: float, n: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Points and outward normals on the four sides and the top of an upright box on the table,
    centred at the origin in xy."""
    g = np.linspace(-half, half, n)
    z = np.linspace(TABLE_TOP_Z, TABLE_TOP_Z + height, n)
    points, normals = [], []
    for axis, sign in ((0, 1), (0, -1), (1, 1), (1, -1)):
        for a in g:
            for h in z:
                p = np.zeros(3)
                p[axis], p[1 - axis], p[2] = sign * half, a, h
                nrm = np.zeros(3)
                nrm[axis] = sign
                points.append(p), normals.append(nrm)
    for a in g:
        for b in g:
            points.append([a, b, TABLE_TOP_Z + height]), normals.append([0.0, 0.0, 1.0])
    return np.array(points), np.array(normals)


def _index(cloud, normals, position, normal) -> int:
    d = np.linalg.norm(cloud - position, axis=1) + 10 * np.linalg.norm(normals - normal, axis=1)
    return int(np.argmin(d))


def test_a_side_point_is_lowered_to_the_push_height_keeping_its_side():
    cloud, normals = _box_cloud(0.03, 0.16)
    i = _index(cloud, normals, [0.03, 0.0, TABLE_TOP_Z + 0.1], [1.0, 0.0, 0.0])
    point, normal = push_contact(cloud, normals, i, LOW)
    np.testing.assert_array_equal(normal, normals[i])
    np.testing.assert_allclose(point[:2], cloud[i][:2])  # the same side, the same place on it
    # The executor's pre-contact point (point + distance * normal) lands at the push height.
    pre = point + LOW.pre_contact_distance * normal
    assert pre[2] == pytest.approx(TABLE_TOP_Z + LOW.push_height)
    # push_height 0: the chosen point itself.
    same, _ = push_contact(cloud, normals, i, PrimitiveConfig(push_height=0.0))
    np.testing.assert_array_equal(same, cloud[i])


def test_top_faces_and_points_already_low_keep_their_own_height():
    cloud, normals = _box_cloud(0.03, 0.16)
    top = _index(cloud, normals, [0.0, 0.0, TABLE_TOP_Z + 0.16], [0.0, 0.0, 1.0])
    np.testing.assert_array_equal(push_contact(cloud, normals, top, LOW)[0], cloud[top])
    low = _index(cloud, normals, [0.03, 0.0, TABLE_TOP_Z + 0.005], [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(push_contact(cloud, normals, low, LOW)[0], cloud[low])


def test_an_object_wider_below_stops_the_fingers_above_it():
    """A step: a tall narrow block on a wide base 3 cm high. Below the upper block's contact the
    base reaches out under the pre-contact point, so the fingers stop FINGER_DEPTH above the
    base's top instead of going down to the push height (inside the base)."""
    upper, n_upper = _box_cloud(0.02, 0.15)
    base, n_base = _box_cloud(0.08, 0.03)
    keep = base[:, 2] > TABLE_TOP_Z + 0.029  # the base's top face and upper edge
    cloud = np.concatenate([upper, base[keep]])
    normals = np.concatenate([n_upper, n_base[keep]])
    i = _index(cloud, normals, [0.02, 0.0, TABLE_TOP_Z + 0.1], [1.0, 0.0, 0.0])
    point, normal = push_contact(cloud, normals, i, LOW)
    pre = point + LOW.pre_contact_distance * normal
    near = np.linalg.norm(cloud[:, :2] - pre[:2], axis=1) < FINGER_COLUMN_RADIUS
    assert near.any()
    assert pre[2] == pytest.approx(cloud[near, 2].max() + FINGER_DEPTH)
    assert pre[2] > TABLE_TOP_Z + LOW.push_height


def test_leaning_fingers_point_down_and_toward_the_surface_with_the_narrow_side_facing_it():
    from corn_drake.systems.control.primitive_executor import facing_rotation

    facing = np.array([0.6, 0.8])  # the outward normal's horizontal direction
    R = facing_rotation(np.eye(3), facing, np.deg2rad(30))
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    toward = -np.array([0.6, 0.8, 0.0])
    z = R[:, 2]  # the fingers' direction: 30 degrees from straight down, toward the surface
    assert np.degrees(np.arccos(-z[2])) == pytest.approx(30.0)
    horizontal = np.array([z[0], z[1], 0.0])
    assert horizontal @ toward > 0 and np.linalg.norm(np.cross(horizontal, toward)) < 1e-12
    # The narrow side (x) stays in the vertical plane of the normal, so it faces the surface.
    assert abs(R[:, 0] @ np.cross([0.0, 0.0, 1.0], toward)) < 1e-12
    # No lean: the rotation the executor always held.
    np.testing.assert_allclose(facing_rotation(np.eye(3), facing, 0.0)[:, 2], [0, 0, -1])


def test_the_fingers_lean_only_where_the_object_reaches_the_palm():
    """A side contact on an object whose top is above the palm's lower edge at the pre-contact
    point leans the fingers; a flat one (a book) keeps them vertical, whose lowest corners would
    otherwise come within millimetres of the table."""
    from corn_drake.config.scene import ControllerConfig
    from corn_drake.systems.control.primitive_executor import (_LEAN, PALM_ABOVE_TOOL,
                                                               PrimitivePlanner, facing_rotation,
                                                               make_primitive)

    cfg = PrimitiveConfig(push_height=0.02, finger_tilt_deg=30)
    planner = PrimitivePlanner(cfg, ControllerConfig())
    point, normal = np.array([0.0, 0.0, TABLE_TOP_Z + 0.02]), np.array([1.0, 0.0, 0.0])
    primitive = make_primitive(point, normal, [-1.0, 0.0, 0.0], 0, 1)
    tool_p, tool_R = np.array([0.0, 0.0, TABLE_TOP_Z + 0.3]), facing_rotation(np.eye(3), [0, 0])
    pre_z = point[2]  # a horizontal normal: the pre-contact point is as high as the point
    for top_z, lean in ((pre_z + PALM_ABOVE_TOOL + 0.03, np.deg2rad(30)),
                        (pre_z + PALM_ABOVE_TOOL - 0.01, 0.0)):
        memory, _ = planner.plan(planner.initial_memory(), tool_p, tool_R, top_z,
                                 lambda: primitive)
        assert memory[_LEAN] == pytest.approx(lean)


def test_push_height_is_range_checked():
    from corn_drake.config.plumbing.bounds import check_bounds
    from corn_drake.errors import InputError

    with pytest.raises(InputError, match="push_height"):
        check_bounds(PrimitiveConfig(push_height=-0.01))
    with pytest.raises(InputError, match="finger_tilt_deg"):
        check_bounds(PrimitiveConfig(finger_tilt_deg=75))


# ---------------------------------------------------------------- the real diagram, one push
def _push_tall_box(primitive: PrimitiveConfig) -> tuple[bool, float, float]:
    """One primitive on an upright 5 x 5 x 10 cm box, at a side point 6 cm up, straight inward
    (0.7 x push_distance: ~6.5 cm past the surface), horizontally: (reached, how far the box
    moved in xy, how far its up axis tilted, rad)."""
    from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
    from corn_drake.rl.envs.primitive_env import PrimitiveEnv
    from corn_drake.transforms import quat_wxyz_to_matrix, up_angle

    cfg = load_primitive_env_config("push")
    cfg.scene.object.size = [0.05, 0.05, 0.10]
    env = PrimitiveEnv(cfg, primitive)
    # The first episode whose start stands the box on an end (the task samples its stable
    # poses; most lie it down).
    for seed in range(30):
        obs, _ = env.reset(seed=seed)
        if np.ptp(obs["cloud"][:, 2]) > 0.09:
            break
    else:
        pytest.fail("no upright start among 30 episodes")
    before = env.object_pose()
    cloud, normals = obs["cloud"], obs["normals"]
    side = np.flatnonzero((np.abs(normals[:, 2]) < 0.1)
                          & (np.abs(cloud[:, 2] - cloud[:, 2].min() - 0.06) < 0.015))
    assert len(side) > 0
    i = int(side[np.argmax(normals[side, 0])])  # the side facing +x most directly
    inward = -np.array([normals[i, 0], normals[i, 1], 0.0])
    _, _, _, _, info = env.step({"point": i, "motion": 0.7 * inward / np.linalg.norm(inward)})
    after = env.object_pose()
    tilt = up_angle(quat_wxyz_to_matrix(after[3:]), quat_wxyz_to_matrix(before[3:]))
    return info["reached"], float(np.linalg.norm(after[:2] - before[:2])), float(tilt)


def test_a_tall_box_tips_under_the_palm_and_slides_pushed_low_with_leaning_fingers():
    """With vertical fingers the palm (2.1 cm deeper than the fingers, 4.5 cm above the tool
    point) meets the box first and tips it, even with the fingers lowered to 2 cm; lowered
    fingers leaning 30 degrees (the palm leaning away) slide it upright."""
    reached, _, tilt = _push_tall_box(PrimitiveConfig(push_height=0.0, finger_tilt_deg=0.0))
    assert reached and tilt > 0.5  # toppled (the failure table's tipped rule)
    reached, _, tilt = _push_tall_box(PrimitiveConfig(push_height=0.02, finger_tilt_deg=0.0))
    assert reached and tilt > 0.5
    reached, moved, tilt = _push_tall_box(PrimitiveConfig(push_height=0.02, finger_tilt_deg=30,
                                                          approach_steps=30))
    assert reached and tilt < 0.2 and moved > 0.02  # slid upright
