"""Friction: the per-geometry coefficients Drake combines (2ab/(a+b)) give the paper's averages."""

import numpy as np
import pytest
from pydrake.multibody.plant import CalcContactFrictionFromSurfaceProperties
from pydrake.systems.framework import DiagramBuilder

from corn_drake.config.scene import SceneConfig
from corn_drake.errors import InputError
from corn_drake.scene.builder import build_scene
from corn_drake.scene.friction import geometry_friction
from corn_drake.scene.objects import box_spec
from corn_drake.scene.randomization import PhysicsSample, apply_physics


def _scene():
    builder = DiagramBuilder()
    scene = build_scene(builder, SceneConfig(), box_spec([0.09, 0.07, 0.05], 0.3))
    diagram = builder.Build()
    return scene, diagram.CreateDefaultContext()


def _friction(scene, root_context, gid):
    """The Coulomb friction SceneGraph holds for `gid` in this context."""
    sg_ctx = scene.scene_graph.GetMyContextFromRoot(root_context)
    inspector = scene.scene_graph.get_query_output_port().Eval(sg_ctx).inspector()
    return inspector.GetProximityProperties(gid).GetProperty("material", "coulomb_friction")


def _combined(scene, ctx, a, b) -> float:
    return CalcContactFrictionFromSurfaceProperties(_friction(scene, ctx, a),
                                                    _friction(scene, ctx, b)).dynamic_friction()


@pytest.mark.parametrize("obj, table, finger", [(0.7, 0.3, 1.2), (1.0, 0.3, 1.5), (0.7, 0.8, 1.0),
                                                (0.2, 0.8, 1.5)])
def test_drake_combines_the_written_coefficients_into_the_paper_average(obj, table, finger):
    scene, ctx = _scene()
    sample = PhysicsSample(mass=0.3, scale=1.0, object_friction=obj, table_friction=table,
                           finger_friction=finger, restitution=0.0, torque_noise_std=0.0)
    apply_physics(scene, sample, ctx, 1.0)
    o, t = scene.object_geometries[0], scene.table_geometries[0]
    # Writing the sampled values themselves gave 2*0.7*0.3/1.0 = 0.42 for the first case.
    assert _combined(scene, ctx, o, t) == pytest.approx((obj + table) / 2, rel=1e-12)
    for f in scene.finger_geometries:
        assert _combined(scene, ctx, o, f) == pytest.approx((obj + finger) / 2, rel=1e-12)
    assert sample.as_observation()[1:4].tolist() == [table, obj, finger]  # the policy sees these


def test_the_scene_is_built_with_the_nominal_average():
    from corn_drake.scene.builder import DEFAULT_OBJECT_FRICTION, DEFAULT_TABLE_FRICTION

    scene, ctx = _scene()
    assert _combined(scene, ctx, scene.object_geometries[0], scene.table_geometries[0]) == \
        pytest.approx((DEFAULT_OBJECT_FRICTION + DEFAULT_TABLE_FRICTION) / 2, rel=1e-12)


def test_coefficients_stay_positive_and_bounded_for_any_positive_frictions():
    rng = np.random.default_rng(0)
    for obj, table, finger in np.exp(rng.uniform(np.log(1e-3), np.log(1e3), (500, 3))):
        mu = geometry_friction(obj, table, finger)
        targets = ((obj + table) / 2, (obj + finger) / 2)
        for value in (mu.object, mu.table, mu.finger):
            assert np.isfinite(value) and min(targets) / 2 < value <= max(targets) * (1 + 1e-12)


def test_bad_friction_is_named():
    for bad in (0.0, -0.5, float("nan"), float("inf")):
        with pytest.raises(InputError, match="table_friction"):
            geometry_friction(0.8, bad, 1.0)


def test_env_observes_the_sampled_frictions_and_simulates_their_average():
    from corn_drake.rl.envs.teacher_env import TeacherEnv

    env = TeacherEnv()
    obs, _ = env.reset(seed=4)
    phys = env.episode.physics
    np.testing.assert_allclose(obs["physics"], phys.as_observation())
    scene = env.scene
    combined = _combined(scene, env.context, scene.object_geometries[0], scene.table_geometries[0])
    assert combined == pytest.approx((phys.object_friction + phys.table_friction) / 2, rel=1e-12)
