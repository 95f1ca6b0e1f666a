"""Pushes shortened so the object stays on the table (PrimitiveConfig.keep_on_table,
systems/edge_push.py): the arithmetic on known cases, the planner's use of it, and a real
push toward a table edge that the option stops short of it."""

import numpy as np
import pytest

from corn_drake.config.diagram_files import load_primitive_env_config
from corn_drake.config.primitive import PrimitiveConfig
from corn_drake.config.scene import ControllerConfig
from corn_drake.rl.envs.primitive_env import PrimitiveEnv
from corn_drake.systems.edge_push import push_kept_on_table
from corn_drake.systems.primitive_executor import _PUSH, PrimitivePlanner, make_primitive

HALF, MARGIN, GAP = np.array([0.2, 0.25]), 0.03, 0.04


def test_a_push_toward_the_edge_ends_where_the_object_keeps_the_margin():
    # Centre 2 cm short of the limit (0.17): 4 cm of air, then 2 cm of carrying.
    push = push_kept_on_table([0.15, 0.0, -0.02], [0.15, 0.0], HALF, MARGIN, GAP)
    np.testing.assert_allclose(push, [0.06, 0.0, -0.02])  # the vertical part kept
    # Diagonal: the y limit (0.22) binds first; the direction is kept.
    push = push_kept_on_table([0.1, 0.1, 0.0], [0.0, 0.2], HALF, MARGIN, GAP)
    carried = 0.02 / (1 / np.sqrt(2))
    np.testing.assert_allclose(push[:2], (GAP + carried) * np.array([1, 1]) / np.sqrt(2))


@pytest.mark.parametrize("push, centre", [
    ([-0.15, 0.0, 0.0], [0.15, 0.0]),  # away from the near edge
    ([0.15, 0.0, 0.0], [-0.1, 0.0]),  # toward the far edge, stopping 12 cm short of it
    ([0.03, 0.0, 0.0], [0.19, 0.0]),  # all air: the tool never reaches the object
    ([0.0, 0.0, -0.1], [0.19, 0.24]),  # straight down
])
def test_pushes_that_keep_the_object_on_the_table_are_unchanged(push, centre):
    np.testing.assert_array_equal(push_kept_on_table(push, centre, HALF, MARGIN, GAP), push)


def test_an_object_already_past_the_limit_is_only_reached_not_pushed_further_out():
    push = push_kept_on_table([0.0, -0.15, 0.0], [0.0, -0.23], HALF, MARGIN, GAP)
    np.testing.assert_allclose(push, [0.0, -GAP, 0.0])


def test_the_planner_shortens_the_push_only_when_asked():
    primitive = make_primitive([0.1, 0.0, 0.45], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0, 1)
    tool = np.array([0.0, 0.0, 0.7])
    pushes = []
    for keep in (False, True):
        planner = PrimitivePlanner(PrimitiveConfig(keep_on_table=keep), ControllerConfig(), HALF)
        memory, _ = planner.plan(planner.initial_memory(), tool, np.eye(3), 0.5,
                                 lambda: primitive, object_xy=np.array([0.12, 0.0]))
        pushes.append(memory[_PUSH])
    np.testing.assert_allclose(pushes[0], [0.15, 0.0, 0.0])
    np.testing.assert_allclose(pushes[1], [GAP + 0.05, 0.0, 0.0])  # 0.17 - 0.12 carried
    with pytest.raises(ValueError, match="table's size"):
        PrimitivePlanner(PrimitiveConfig(keep_on_table=True), ControllerConfig())
    planner = PrimitivePlanner(PrimitiveConfig(keep_on_table=True), ControllerConfig(), HALF)
    with pytest.raises(ValueError, match="object's position"):
        planner.plan(planner.initial_memory(), tool, np.eye(3), 0.5, lambda: primitive)


TABLE_X = 0.24  # a narrow table: the box starts a few cm from its x edges


def _push_toward_the_edge(keep: bool) -> tuple[float, float]:
    """A box on a table 24 cm deep and a full side push toward the table's nearer x edge:
    (how far the box's centre is from the table's centre line along the push, before and
    after)."""
    cfg = load_primitive_env_config("push")
    cfg.scene.table_size = [TABLE_X, *cfg.scene.table_size[1:]]
    env = PrimitiveEnv(cfg, PrimitiveConfig(keep_on_table=keep, table_margin=MARGIN))
    obs, _ = env.reset(seed=4)
    start = obs["object_position"]
    sign = 1.0 if start[0] >= 0 else -1.0  # toward the nearer edge
    normals = obs["normals"]
    index = int(np.argmin(sign * normals[:, 0] + 3 * np.abs(normals[:, 2])))  # the far side
    env.step({"point": index, "motion": [sign, 0.0, 0.0]})
    return sign * float(start[0]), sign * float(env.object_pose()[0])


def test_a_real_push_toward_the_edge_stops_short_of_it_only_with_the_option():
    limit = TABLE_X / 2 - MARGIN
    before, kept = _push_toward_the_edge(True)
    before_free, free = _push_toward_the_edge(False)
    assert before == before_free and limit - before < 0.08  # the push can cross the line
    # The predicted carry is an estimate (the air gap along the push, the box's slide after
    # the tool stops): the centre stays within 1.5 cm of the margin's line.
    assert kept <= limit + 0.015
    assert free > kept + 0.02  # the full push carries it much further


def test_the_view_draws_the_shortened_push_the_executor_ran():
    """The arrow ends where the executor's push ends: motion x push_distance shortened for the
    edge (computed here from the observation's box corners), not the motion as sent."""
    from pydrake.geometry import Meshcat

    from corn_drake.viz.primitive_view import primitive_path
    from tests.test_primitive_executor import _animations, _status

    cfg = load_primitive_env_config("push")
    cfg.scene.table_size = [TABLE_X, *cfg.scene.table_size[1:]]
    meshcat = Meshcat()
    primitive = PrimitiveConfig(keep_on_table=True, table_margin=MARGIN)
    env = PrimitiveEnv(cfg, primitive, meshcat=meshcat)
    obs, _ = env.reset(seed=4)
    sign = 1.0 if obs["object_position"][0] >= 0 else -1.0
    index = int(np.argmin(sign * obs["normals"][:, 0] + 3 * np.abs(obs["normals"][:, 2])))
    motion = np.array([sign, 0.0, 0.0])
    centre = obs["object_keypoints"].reshape(-1, 3)[:, :2].mean(axis=0)
    env.step({"point": index, "motion": motion})
    status = _status(env)
    expected = push_kept_on_table(motion * primitive.push_distance, centre,
                                  np.asarray(cfg.scene.table_size[:2]) / 2,
                                  MARGIN, primitive.pre_contact_distance)
    assert np.linalg.norm(expected) < 0.9 * primitive.push_distance  # it was shortened
    np.testing.assert_allclose(status["push"], expected, atol=1e-9)
    view = env.diagram.GetSubsystemByName("primitive_view")
    _, _, places = _animations(meshcat.StaticHtml(), view.path)
    np.testing.assert_allclose(places[f"{primitive_path(view.path, 1)}/arrow/head"],
                               status["pre_contact"] + expected, atol=1e-6)
