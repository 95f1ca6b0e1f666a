"""Stable poses are kept only if they hold under both contact settings; the kept share is
reported."""

import numpy as np
import pytest
import trimesh

from corn_drake.assets.processing.hulls import obj_text
from pydrake.math import RotationMatrix

from corn_drake.assets.processing.stable_poses import (DropConfig, _quat, _TableSim, _touching,
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
    from corn_drake.assets.processing.process import kept_fraction
    from corn_drake.commands.datasets.objects import _stable_pose_summary

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


def _support_margin(pose: np.ndarray, vertices: np.ndarray, com: np.ndarray) -> float:
    """Placed at `pose`, how far (m) the centre of mass projects inside the polygon of the hull
    vertices within 1e-5 m of the lowest one (negative: outside). Written apart from
    stable_poses.stable_faces, so it checks the stored poses, not that function's own view."""
    from scipy.spatial import ConvexHull

    from corn_drake.transforms import quat_wxyz_to_matrix

    R = quat_wxyz_to_matrix(pose[3:])
    world = vertices @ R.T + pose[:3]
    support = world[world[:, 2] < world[:, 2].min() + 1e-5][:, :2]
    polygon = ConvexHull(support)
    return float(-(polygon.equations[:, :2] @ (R @ com)[:2] + polygon.equations[:, 2]).max())


def _recording_rests(monkeypatch):
    """The object-frame down direction of every drop's rest, as find_stable_poses sees it."""
    from corn_drake.assets.processing import stable_poses

    rests, face_of = [], stable_poses.StableFaces.face_of
    monkeypatch.setattr(stable_poses.StableFaces, "face_of",
                        lambda self, down, max_angle: rests.append(down) or
                        face_of(self, down, max_angle))
    return rests


def test_stored_poses_do_not_follow_the_simulations_last_digits(tmp_path, monkeypatch):
    """Another CPU or build changes the drops' floating point; emulated by starting every drop
    (and every check of a pose) 1e-12 to 1e-6 m higher. The simulated rests move, but the
    stored poses come from the stable hull faces the drops rest on, so they are byte for byte
    the same arrays, on the 1e-9 grid, each with its lowest vertex on the table top and the
    centre of mass projecting inside the face it rests on."""
    from corn_drake.assets.processing import stable_poses
    from corn_drake.scene.objects import TABLE_TOP_Z
    from corn_drake.transforms import quat_wxyz_to_matrix

    spec, vertices = _stool(tmp_path)
    cfg = DropConfig(drops=30, height=0.005)
    rests = _recording_rests(monkeypatch)
    poses, _ = find_stable_poses(spec, vertices, np.random.default_rng(0), cfg)
    exact_rests = np.array(rests)
    exact = stable_poses.RigidTransform
    for eps in (1e-12, 1e-9, 1e-6):
        monkeypatch.setattr(stable_poses, "RigidTransform", lambda R, p, eps=eps: exact(
            R, np.asarray(p, float) + [0.0, 0.0, eps]))
        rests.clear()
        again, _ = find_stable_poses(spec, vertices, np.random.default_rng(0), cfg)
        # The emulation reaches the simulation (else the comparison below proves nothing)...
        assert not np.array_equal(np.array(rests), exact_rests), eps
        # ...and the stored bytes do not follow it.
        assert again.tobytes() == poses.tobytes(), eps
    assert len(poses) == 5
    assert np.array_equal(poses, np.round(poses, stable_poses.GRID_DECIMALS))
    for p in poses:
        lowest = (vertices @ quat_wxyz_to_matrix(p[3:]).T)[:, 2].min() + p[2]
        assert lowest == pytest.approx(TABLE_TOP_Z, abs=2e-9)
        assert _support_margin(p, vertices, spec.com) > cfg.stable_margin


def _leaning_tower() -> np.ndarray:
    """A 2 x 2 x 10 cm box sheared by 5 cm along x: its centre of mass lies beyond its base."""
    base = np.array([[x, y, 0.0] for x in (0.0, 0.02) for y in (0.0, 0.02)])
    top = base + [0.05, 0.0, 0.1]
    vertices = np.concatenate([base, top])
    return vertices - vertices.mean(axis=0)  # a parallelepiped's centroid is its mean vertex


def test_stable_faces_are_those_holding_the_centre_of_mass():
    from corn_drake.assets.processing.stable_poses import stable_faces

    cfg = DropConfig()
    faces = stable_faces(_leaning_tower(), np.zeros(3), cfg)
    # It lies on its four long sides; it stands on neither end (the centre of mass projects
    # 1.5 cm beyond each).
    assert len(faces.normals) == 4 and np.all(np.abs(faces.normals[:, 2]) < 0.9)
    assert np.all(faces.margins > cfg.stable_margin)
    # A box: all six faces, none clustered with another, the larger faces first.
    box = np.array([[x, y, z] for x in (-0.05, 0.05) for y in (-0.02, 0.02) for z in (-0.01, 0.01)])
    faces = stable_faces(box, np.zeros(3), cfg)
    assert len(faces.normals) == 6 and list(faces.cluster) == list(range(6))
    assert np.all(np.diff(faces.margins) <= 0)


def test_a_flat_face_printed_to_8_decimals_is_still_one_face():
    """A 32-sided cylinder turned so that its caps are not axis-aligned, its vertices rounded as
    the library's OBJ files round them: the caps are fans of triangles a few 1e-9 m uneven, each
    too small to hold the centre of mass alone; the object still stands on each cap."""
    from scipy.spatial.transform import Rotation

    from corn_drake.assets.processing.stable_poses import stable_faces

    axis = Rotation.from_rotvec([0.3, -0.7, 0.2])
    mesh = trimesh.creation.cylinder(radius=0.03, height=0.05, sections=32)
    vertices = np.round(axis.apply(mesh.vertices), 8)
    cfg = DropConfig()
    faces = stable_faces(vertices, np.zeros(3), cfg)
    up = axis.apply([0.0, 0.0, 1.0])
    caps = [i for i, n in enumerate(faces.normals) if abs(n @ up) > 1 - 1e-6]
    # Each cap triangle, judged with the whole cap beneath it, holds; a cap is one cluster.
    assert len({faces.cluster[i] for i in caps}) == 2
    assert all(faces.margins[i] > 0.02 for i in caps)
    # The sides: one per facet of the 32-gon (each 0.196 rad from the next), lying.
    assert len(set(faces.cluster.tolist())) == 34


def test_an_ellipsoid_with_no_large_face_keeps_a_pose_it_rests_on(tmp_path):
    """The unseen build's ellipsoid (procedural seed 2383511823) has only small hull triangles;
    posing it on the largest face near where a drop came to rest lost it ("no stable pose
    found"). Its poses now rest where it holds: on the vertex at a pole of its shortest axis
    (where the drops come to rest on the compliant table) or on a face holding its centre of
    mass."""
    from corn_drake.assets.families import make_family_mesh
    from corn_drake.assets.processing.process import ProcessConfig, process_object

    seed = 2383511823
    cfg = ProcessConfig(drops=DropConfig(drops=12))
    fields = process_object(make_family_mesh("ellipsoid", seed), "ellipsoid_x", tmp_path,
                            np.random.default_rng(seed), cfg, convex=True, cache_dir=None)
    assert fields["num_stable_poses"] >= 1, fields["drops"]
    poses = np.load(tmp_path / fields["stable_poses"])
    from corn_drake.assets.processing.process import obj_vertices

    vertices = np.concatenate([obj_vertices((tmp_path / h).read_text()) for h in fields["hulls"]])
    from scipy.spatial import ConvexHull

    from corn_drake.transforms import quat_wxyz_to_matrix

    hull = ConvexHull(vertices)
    distance = np.linalg.norm(vertices, axis=1)  # the centre of mass is the origin
    for p in poses:
        world = vertices @ quat_wxyz_to_matrix(p[3:]).T + p[:3]
        lowest = np.flatnonzero(world[:, 2] < world[:, 2].min() + 1e-5)
        if len(lowest) >= 3:  # on a face: the centre of mass projects inside it
            assert _support_margin(p, vertices, np.zeros(3)) > cfg.drops.stable_margin
            continue
        # On a vertex (its shortest axis's pole): the centre of mass straight above it, and
        # every neighbour on the hull farther from it, so tipping lifts the centre of mass.
        k = lowest[0]
        assert np.linalg.norm(world[k, :2] - p[:2]) < 1e-6
        neighbours = {int(j) for tri in hull.simplices if k in tri for j in tri} - {k}
        assert neighbours and all(distance[j] > distance[k] for j in neighbours)
