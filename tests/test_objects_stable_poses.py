"""Stable poses are kept only if they hold under both contact settings; the kept share is
reported."""

import numpy as np
import pytest
import trimesh

from corn_drake.assets.hulls import obj_text
from pydrake.math import RotationMatrix

from corn_drake.assets.stable_poses import (DropConfig, _quat, _TableSim, _touching,
                                            find_stable_poses, second_setting)
from corn_drake.config.scene import SceneConfig
from corn_drake.scene.objects import ObjectSpec


def _box(lo, hi) -> trimesh.Trimesh:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return trimesh.creation.box(hi - lo).apply_translation((lo + hi) / 2)


def _stool(tmp_path) -> tuple[ObjectSpec, np.ndarray]:
    """A 0.5 kg two-legged stool (legs 1 x 4 cm, 8 cm tall, 4 cm apart, a 1 cm top) whose legs
    have the same shape but not the same hulls: one leg is one hull, the other a 3 mm foot hull
    under a second hull.

    Rigid hulls on the compliant training table: the split changes nothing, it stands. Compliant
    hulls on a rigid table: a hull's pressure grows from its faces to its centroid, so the one-hull
    leg (centroid 4 cm up) is ~25x softer than the foot (1.5 mm up), sinks ~2 mm more under
    2.5 N and tilts the stool beyond 0.05 rad. Measured: with both legs one hull, or at 0.1 kg,
    it stands in both settings."""
    x0 = 0.02
    parts = [_box([-x0 - 0.005, -0.02, 0.0], [-x0 + 0.005, 0.02, 0.08]),
             _box([x0 - 0.005, -0.02, 0.0], [x0 + 0.005, 0.02, 0.003]),
             _box([x0 - 0.005, -0.02, 0.003], [x0 + 0.005, 0.02, 0.08]),
             _box([-x0 - 0.005, -0.02, 0.08], [x0 + 0.005, 0.02, 0.09])]
    volumes = np.array([p.volume for p in parts])
    com = sum(p.center_mass * v for p, v in zip(parts, volumes)) / volumes.sum()
    paths = []
    for i, part in enumerate(parts):
        part.apply_translation(-com)
        paths.append(tmp_path / f"hull_{i}.obj")
        paths[-1].write_text(obj_text(part))
    union = trimesh.util.concatenate(parts)
    vertices = np.concatenate([p.vertices for p in parts])
    spec = ObjectSpec(name="stool", mass=0.5, unit_inertia=union.moment_inertia / union.mass,
                      com=np.zeros(3), cloud=np.zeros((1, 6)), stable_poses=np.zeros((0, 7)),
                      radius=float(np.linalg.norm(vertices, axis=1).max()),
                      bbox_corners=np.zeros((8, 3)), hull_paths=paths)
    return spec, vertices


def _up_axis(pose) -> np.ndarray:
    """The object-frame direction pointing up in `pose`."""
    return RotationMatrix(_quat(pose[3:])).matrix().T @ np.array([0.0, 0.0, 1.0])


def test_standing_holds_in_the_training_setting_only(tmp_path):
    spec, vertices = _stool(tmp_path)
    cfg = DropConfig()
    standing = _touching(np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]), vertices)
    assert _TableSim(spec, SceneConfig()).holds(standing, 1.0, cfg.verify_position,
                                                cfg.verify_angle)
    assert not _TableSim(spec, second_setting(SceneConfig(), cfg)).holds(
        standing, 1.0, cfg.second_position, cfg.second_angle)


def test_a_pose_only_the_training_setting_holds_is_dropped_and_counted(tmp_path):
    spec, vertices = _stool(tmp_path)
    # The first 6 drops put each principal axis down; from 5 mm the stool lands on its legs and
    # stays (from 20 cm it topples).
    cfg = DropConfig(drops=30, height=0.005)
    poses, stats = find_stable_poses(spec, vertices, np.random.default_rng(0), cfg)
    # Standing, upside down and on each of the four sides held in the training setting; all
    # but standing hold in the second setting too.
    ups = sorted(tuple(np.round(_up_axis(p)).astype(int)) for p in poses)
    assert ups == [(-1, 0, 0), (0, -1, 0), (0, 0, -1), (0, 1, 0), (1, 0, 0)]
    assert stats["verified"] == stats["held_second_setting"] + 1 == len(poses) + 1
    assert stats["second_setting_s"] > 0


def test_kept_fraction_is_the_share_of_training_poses_the_second_setting_keeps():
    from corn_drake.assets.process import kept_fraction
    from corn_drake.commands.objects import _stable_pose_summary

    assert kept_fraction({"verified": 4, "held_second_setting": 3}) == 0.75
    assert kept_fraction({"verified": 0, "held_second_setting": 0}) == 0.0
    from corn_drake.assets.manifest import LibraryObject

    objects = [LibraryObject(id="stool", drops={"verified": 4, "held_second_setting": 3},
                             stable_pose_kept_fraction=0.75),
               LibraryObject(id="cuboid_000", drops={"verified": 6, "held_second_setting": 6},
                             stable_pose_kept_fraction=1.0)]
    lines = _stable_pose_summary(objects)
    assert lines[0].startswith("stable poses holding under both contact settings: 9 of the 10")
    assert lines[1:] == ["  stool: kept 3 of 4 (75%)"]  # only objects that lost poses are listed


def test_stored_poses_do_not_follow_the_simulations_last_digits(tmp_path, monkeypatch):
    """Another CPU or build changes the drops' floating point; emulated by starting every drop
    1e-9 m higher. The stored poses come from the hull faces the drops rest on, so they are
    the same arrays, on the 1e-9 grid, each with its lowest vertex on the table top."""
    from corn_drake.assets import stable_poses
    from corn_drake.scene.objects import TABLE_TOP_Z
    from corn_drake.transforms import quat_wxyz_to_matrix

    spec, vertices = _stool(tmp_path)
    cfg = DropConfig(drops=30, height=0.005)
    poses, _ = find_stable_poses(spec, vertices, np.random.default_rng(0), cfg)
    exact = stable_poses.RigidTransform
    monkeypatch.setattr(stable_poses, "RigidTransform",
                        lambda R, p: exact(R, np.asarray(p, float) + [0.0, 0.0, 1e-9]))
    again, _ = find_stable_poses(spec, vertices, np.random.default_rng(0), cfg)
    assert len(poses) == 5 and np.array_equal(poses, again)
    assert np.array_equal(poses, np.round(poses, stable_poses.GRID_DECIMALS))
    for p in poses:
        lowest = (vertices @ quat_wxyz_to_matrix(p[3:]).T)[:, 2].min() + p[2]
        assert lowest == pytest.approx(TABLE_TOP_Z, abs=2e-9)
