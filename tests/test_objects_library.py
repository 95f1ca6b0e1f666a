"""A small procedural library: manifest, files, clouds on the surface, stable poses, scene use."""

import json

import numpy as np
import open3d as o3d
import pytest
import trimesh
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from corn_drake.assets.library import (build_procedural, list_objects, load_object_spec,
                                       read_manifest)
from corn_drake.assets.manifest import write_manifest
from corn_drake.assets.processing.process import ProcessConfig
from corn_drake.config.scene import SceneConfig
from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.rl.envs.teacher_env import TeacherEnv
from corn_drake.scene.builder import build_table_scene
from corn_drake.transforms import quat_wxyz_to_matrix, rotation_angle

pytestmark = pytest.mark.slow  # the module's library takes minutes to build

# Every field a built object must carry (unseen_group is None for train objects).
BUILT_FIELDS = ("id", "source", "family", "split", "radius", "mass", "thin", "hulls", "visual",
                "cloud", "stable_poses", "bbox_corners", "unit_inertia", "num_hulls",
                "num_stable_poses", "drops", "stable_pose_kept_fraction", "hull_volume_ratio")


@pytest.fixture(scope="module")
def library(tmp_path_factory):
    out = tmp_path_factory.mktemp("lib")
    cfg = ProcessConfig()
    cfg.drops.drops = 24
    # 16 objects: one member of every family (the two unseen families included) + 2 more.
    build_procedural(out, 16, seed=5, cfg=cfg, progress=False)
    return out


def test_manifest_files_and_splits(library):
    manifest = read_manifest(library)
    assert manifest.objects and set(o.split for o in manifest.objects) == {"train", "unseen"}
    for o in manifest.objects:
        assert all(getattr(o, f) not in (None, "") for f in BUILT_FIELDS), o
        assert o.extra == {}  # the builder writes only fields the schema names
        assert 0.05 - 1e-9 <= o.radius <= 0.10 + 1e-9
        cloud = np.load(library / o.cloud)
        assert cloud.shape == (2048, 6)
        poses = np.load(library / o.stable_poses)
        assert poses.shape == (o.num_stable_poses, 7) and len(poses) > 0
        assert np.allclose(poses[:, :2], 0) and np.all(poses[:, 2] > 0.4)
        assert 1 <= len(o.hulls) <= 16 and all((library / h).is_file() for h in o.hulls)
    assert sorted(list_objects(library, "unseen") + list_objects(library, "train")) == \
        sorted(o.id for o in manifest.objects)


def test_manifest_round_trips_through_the_typed_schema(library, tmp_path):
    manifest = read_manifest(library)
    write_manifest(tmp_path, manifest)
    assert read_manifest(tmp_path) == manifest
    assert json.loads((tmp_path / "manifest.json").read_text()) == \
        json.loads((library / "manifest.json").read_text())


def test_clouds_lie_on_the_surface(library):
    for o in read_manifest(library).objects[:6]:
        mesh = trimesh.load(library / o.visual, force="mesh")
        cloud = np.load(library / o.cloud)
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(mesh.vertices), o3d.utility.Vector3iVector(mesh.faces))))
        distance = scene.compute_distance(o3d.core.Tensor(cloud[:, :3].astype(np.float32))).numpy()
        assert distance.max() < 1e-4 * o.radius + 1e-6  # float32 queries
        assert np.allclose(np.linalg.norm(cloud[:, 3:], axis=1), 1.0, atol=1e-6)


def test_convex_family_hulls_match_the_mesh_volume(library):
    for o in read_manifest(library).objects:
        assert o.hull_volume_ratio >= 0.99
        if o.num_hulls == 1:
            assert o.hull_volume_ratio == pytest.approx(1.0, abs=1e-3)


def test_stored_stable_poses_are_stable_in_the_training_plant(library):
    """Placed on the table at each stored pose and simulated 1 s: < 1 cm and < 0.05 rad."""
    for object_id in list_objects(library)[:8]:
        spec = load_object_spec(library, object_id)
        builder = DiagramBuilder()
        plant, _, body = build_table_scene(builder, SceneConfig(), spec)
        sim = Simulator(builder.Build())
        ctx = plant.GetMyMutableContextFromRoot(sim.get_mutable_context())
        for pose in spec.stable_poses[:4]:
            X0 = RigidTransform(RotationMatrix(quat_wxyz_to_matrix(pose[3:])), pose[:3])
            sim.get_mutable_context().SetTime(0.0)
            plant.SetFreeBodyPose(ctx, body, X0)
            plant.SetVelocities(ctx, np.zeros(6))
            sim.Initialize()
            sim.AdvanceTo(1.0)
            X1 = plant.EvalBodyPoseInWorld(ctx, body)
            assert np.linalg.norm(X1.translation() - X0.translation()) < 0.01, object_id
            assert rotation_angle(X1.rotation().matrix() @ X0.rotation().matrix().T) < 0.05, object_id


def test_teacher_env_runs_a_library_object(library):
    cfg = TeacherDiagramConfig()
    cfg.scene.object.kind, cfg.scene.object.library = "library", str(library)
    cfg.scene.object.object_id = list_objects(library, "train")[0]
    env = TeacherEnv(cfg)
    obs, _ = env.reset(seed=0)
    for _ in range(3):
        obs, reward, *_ = env.step(np.zeros(20))
    assert np.isfinite(reward) and obs["cloud"].shape == (512, 3)
    # The env starts the object in one of its stable poses (any yaw).
    start = env.episode.initial_object_pose
    assert any(abs(start[2] - p[2]) < 1e-9 for p in env.scene.object_spec.stable_poses)


def test_a_one_split_build_makes_the_full_builds_objects_exactly(library, tmp_path):
    """`objects --split unseen` (what the shipped weights' cards name) rebuilds, from nothing,
    the same unseen objects as the full build: ids, splits and every file byte for byte."""
    cfg = ProcessConfig()
    cfg.drops.drops = 24
    part = build_procedural(tmp_path, 16, seed=5, cfg=cfg, progress=False, split="unseen")
    full = read_manifest(library)
    unseen = {o.id: o for o in full.objects if o.split == "unseen"}
    assert sorted(o.id for o in part.objects) == sorted(unseen)
    for o in part.objects:
        ref = unseen[o.id]
        assert (o.split, o.unseen_group) == (ref.split, ref.unseen_group)
        files = [o.cloud, o.stable_poses, o.bbox_corners, o.unit_inertia, o.visual, *o.hulls]
        assert files == [ref.cloud, ref.stable_poses, ref.bbox_corners, ref.unit_inertia,
                         ref.visual, *ref.hulls]
        for f in files:
            assert (tmp_path / f).read_bytes() == (library / f).read_bytes(), (o.id, f)
    assert read_manifest(tmp_path).split_rule["split_over_planned"] == 16
    with pytest.raises(Exception, match="split must be"):
        build_procedural(tmp_path, 16, seed=5, cfg=cfg, progress=False, split="test")
