"""The contact-primitive executor in the primitive env and the evaluation diagram: it reaches the
pre-contact pose (on a box and on a 16-hull mug), one env step is one whole primitive, an
unreachable primitive is given up without an error, the location the executor reports is the
policy's own choice, bad env actions are refused by name, and the Meshcat view draws each
primitive live and in HTML recordings."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from pydrake.geometry import Meshcat
from pydrake.math import RotationMatrix

from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
from corn_drake.config.primitive import PrimitiveConfig
from corn_drake.config.scene import ControllerConfig
from corn_drake.contract import ACTION_SLICES
from corn_drake.errors import InputError
from corn_drake.rl.envs.teacher_env import DiagramEnv
from corn_drake.rl.envs.primitive_env import PrimitiveEnv
from corn_drake.scene.objects import TABLE_TOP_Z
from corn_drake.systems.control.low_push import push_contact
from corn_drake.systems.control.primitive_executor import (IDLE, PUSH, RETREAT, SETTLE,
                                                           STATUS_LAYOUT, PrimitivePlanner,
                                                           make_primitive)
from corn_drake.transforms import quat_wxyz_to_matrix, rotation_angle
from corn_drake.viz.attention_view import viridis_rgb
from corn_drake.viz.primitive_view import nearest_locations, primitive_path
from tests.recordings import meshcat_messages

# procedural:mug:<seed> of the library's mug_000 (crc32 of "0:mug_000"): CoACD splits it into
# 16 convex hulls (the most the library allows).
MUG_SEED = 137592312
FPS = 64  # StartRecording's default frame rate


@pytest.fixture(scope="module")
def mug_library(tmp_path_factory):
    """A one-object library holding a procedural mug, built as `corn-drake objects` builds it
    (fewer stable-pose drops: the test needs a pose, not all of them)."""
    from corn_drake.assets.families import make_family_mesh
    from corn_drake.assets.library import SPEC_FIELDS
    from corn_drake.assets.manifest import LibraryObject, Manifest, write_manifest
    from corn_drake.assets.processing.process import ProcessConfig, process_object
    from corn_drake.assets.processing.stable_poses import DropConfig

    out = tmp_path_factory.mktemp("mug_library")
    fields = process_object(make_family_mesh("mug", MUG_SEED), "mug", out,
                            np.random.default_rng(MUG_SEED),
                            ProcessConfig(drops=DropConfig(drops=16)), convex=False,
                            cache_dir=out / ".coacd_cache")
    entry = LibraryObject(id="mug", split="train", family="mug",
                          source=f"procedural:mug:{MUG_SEED}",
                          **{key: fields[key] for key in SPEC_FIELDS})
    write_manifest(out, Manifest(objects=[entry]))
    return out


# The push at the chosen point's own height with vertical fingers: the hand-picked side points
# below (_side_point) are reached by it and a full push sets the box sliding; the shipped low
# push with leaning fingers (PrimitiveConfig's defaults) misses some of them on this box.
AT_THE_POINT = {"push_height": 0.0, "finger_tilt_deg": 0.0}


def _config(obj: str, mug_library=None):
    cfg = load_primitive_env_config("push")
    if obj == "mug":
        o = cfg.scene.object
        o.kind, o.library, o.object_id = "library", str(mug_library), "mug"
    return cfg


def _side_point(env: PrimitiveEnv, obs: dict) -> int:
    """A cloud point on the object's side (normal within ~17 degrees of horizontal), 1-4.5 cm below
    its top so the hand's palm clears the top when the tool is at the pre-contact point, whose
    pre-contact point is farthest from the cloud (the outside of the object, not the inside of
    a mug or its handle)."""
    cloud, normals = obs["cloud"], obs["normals"]
    top = cloud[:, 2].max()
    side = np.flatnonzero((np.abs(normals[:, 2]) < 0.3) & (cloud[:, 2] > top - 0.045)
                          & (cloud[:, 2] < top - 0.01))
    assert len(side) > 0, "no side point near the top"
    planner = env.handles.executor.planner
    pre = np.array([planner.pre_contact(cloud[i], normals[i]) for i in side])
    clearance = np.linalg.norm(pre[:, None] - cloud[None], axis=-1).min(axis=1)
    return int(side[np.argmax(clearance)])


def _inward(normal: np.ndarray) -> np.ndarray:
    """A horizontal push into the surface (the motion of a side push)."""
    return -np.array([normal[0], normal[1], 0.0])


def _status(env: PrimitiveEnv) -> dict:
    s = env.executor_status()
    return {key: s[index] for key, index in STATUS_LAYOUT.items()}


def _tick_through(env: PrimitiveEnv, primitive: np.ndarray, max_ticks: int = 60) -> list[dict]:
    """Runs `primitive` on the agent-less env one policy period at a time (the executor's input
    fixed, as PrimitiveEnv.step does) until the executor is idle with it done. One row per
    tick: the tool position the executor saw at that tick and its status after the tick."""
    env._primitive_port.FixValue(env.context, primitive)
    obs, rows = env._observation(), []
    for _ in range(max_ticks):
        tool = obs["hand_state"][:3].astype(float)
        obs, _, terminated, truncated, info = DiagramEnv.step(env, None)
        assert "sim_error" not in info, info
        rows.append({"tool": tool, **_status(env)})
        if rows[-1]["phase"] == IDLE and rows[-1]["count"] >= 1 or terminated or truncated:
            break
    return rows


def _object_moved(env: PrimitiveEnv, before: np.ndarray) -> tuple[float, float]:
    """(metres, radians) the object moved since pose `before` ([p, q_wxyz])."""
    now = env.object_pose()
    turn = quat_wxyz_to_matrix(now[3:]) @ quat_wxyz_to_matrix(before[3:]).T
    return float(np.linalg.norm(now[:3] - before[:3])), float(rotation_angle(turn))


# ------------------------------------------------------------------------------- reaching

@pytest.mark.parametrize("obj, seed", [("box", 0), ("mug", 2)])
def test_executor_reaches_the_pre_contact_pose(obj, seed, request):
    mug = request.getfixturevalue("mug_library") if obj == "mug" else None
    env = PrimitiveEnv(_config(obj, mug), PrimitiveConfig(**AT_THE_POINT))
    if obj == "mug":
        assert len(env.scene.object_spec.hull_paths) == 16
    cfg = env.primitive_cfg
    obs, _ = env.reset(seed=seed)
    index = _side_point(env, obs)
    point, normal = obs["cloud"][index].astype(float), obs["normals"][index].astype(float)
    primitive = make_primitive(point, normal, _inward(normal), index, 1)
    rows = _tick_through(env, primitive)
    last = rows[-1]
    assert last["phase"] == IDLE and last["count"] == 1 and last["reached"] == 1, last
    # The pre-contact point: pre_contact_distance out along the normal (a side point well
    # above the table: no clamping).
    np.testing.assert_allclose(last["pre_contact"], point + cfg.pre_contact_distance * normal,
                               atol=1e-6)
    # The tick the push began: the tool the executor saw then was within tolerance of it.
    (start,) = [k for k, row in enumerate(rows) if row["phase"] == PUSH and row["ticks"] == 1]
    assert rows[start - 1]["phase"] != PUSH
    assert np.linalg.norm(rows[start]["tool"] - last["pre_contact"]) < cfg.reach_tolerance
    # The same primitive through the gymnasium step: reached, in the same number of ticks.
    obs, _ = env.reset(seed=seed)
    _, _, _, _, info = env.step({"point": index, "motion": _inward(normal)})
    assert info["reached"] is True
    assert info["ticks"] == len(rows)


def test_one_env_step_is_one_whole_primitive():
    env = PrimitiveEnv(_config("box"))
    obs, _ = env.reset(seed=1)
    for expected in (1, 2):
        index = _side_point(env, obs)
        steps = env._steps
        # Short pushes (3 cm): the box stays short of the goal, so no step ends the episode.
        obs, reward, terminated, truncated, info = env.step(
            {"point": index, "motion": 0.3 * _inward(obs["normals"][index])})
        assert not terminated and not truncated
        status = _status(env)
        assert status["count"] == expected and status["phase"] == IDLE
        assert info["ticks"] > 1 and info["ticks"] == env._steps - steps
        assert env.primitives == expected and np.isfinite(reward)
        # The observation carries the same status.
        np.testing.assert_allclose(obs["executor"], env.executor_status(), atol=1e-6)


# ---------------------------------------------------------------------------------- settling

def _planner_after_retreat(settle_steps: int):
    """A planner and its memory at the end of a primitive's retreat (its last tick next)."""
    planner = PrimitivePlanner(PrimitiveConfig(settle_steps=settle_steps), ControllerConfig())
    memory = planner.initial_memory()
    memory[0], memory[1] = RETREAT, planner.cfg.retreat_steps - 1  # _PHASE, _TICKS
    return planner, memory


def _tick(planner, memory, keypoints, tool=(0.5, 0.0, TABLE_TOP_Z + 0.2)):
    offered = np.zeros(len(make_primitive(np.zeros(3), np.zeros(3), np.zeros(3), 0, 0)))
    return planner.plan(memory, np.asarray(tool, float), RotationMatrix().matrix(), 0.2,
                        lambda: offered, keypoints=keypoints)


@pytest.mark.parametrize("drift, ticks", [(0.0, 1), (0.001, 1), (0.005, 5)])
def test_the_hand_waits_for_the_object_to_settle_at_most_settle_steps(drift, ticks):
    """After the retreat the hand holds still until the object's keypoints moved less than
    settle_motion (2 mm) over a tick, or settle_steps (5) ticks have passed."""
    planner, memory = _planner_after_retreat(5)
    corners = np.random.default_rng(0).uniform(-0.05, 0.05, (8, 3))
    memory, _ = _tick(planner, memory, corners)
    assert memory[0] == SETTLE
    for tick in range(1, 20):
        memory, action = _tick(planner, memory, corners + drift * tick)
        # The hand holds where it is.
        np.testing.assert_allclose(action[ACTION_SLICES["position"]], 0.0, atol=1e-12)
        if memory[0] == IDLE:
            break
    assert memory[0] == IDLE and tick == ticks


def test_without_settle_steps_the_retreat_ends_idle_and_keypoints_are_not_needed():
    planner, memory = _planner_after_retreat(0)
    memory, _ = _tick(planner, memory, None)
    assert memory[0] == IDLE
    planner, memory = _planner_after_retreat(3)
    with pytest.raises(ValueError, match="settle_steps needs the object's keypoints"):
        _tick(planner, memory, None)


@pytest.mark.parametrize("field, value", [("settle_steps", -1), ("settle_motion", 0.0)])
def test_a_primitive_env_refuses_a_settle_setting_out_of_range_by_name(field, value):
    with pytest.raises(InputError, match=f"primitive.{field} must be"):
        PrimitiveEnv(_config("box"), PrimitiveConfig(**{field: value}))


def test_a_settling_env_step_returns_with_the_object_still():
    """A hard push sets a box sliding; with settle_steps the step returns only once it has
    stopped (or the steps are spent), and takes longer than the same step without."""
    results = {}
    for settle in (0, 30):
        env = PrimitiveEnv(_config("box"), PrimitiveConfig(settle_steps=settle, **AT_THE_POINT))
        obs, _ = env.reset(seed=0)
        index = _side_point(env, obs)
        _, _, _, _, info = env.step({"point": index, "motion": _inward(obs["normals"][index])})
        results[settle] = (info["ticks"], env.object_still(), _status(env)["phase"])
        assert results[settle][2] == IDLE
    assert not results[0][1] and results[30][1], results  # sliding at the return, then still
    assert results[30][0] > results[0][0], results


# ------------------------------------------------------------------------------- unreachable

def test_a_primitive_out_of_the_arms_reach_is_given_up_and_leaves_the_object():
    env = PrimitiveEnv(_config("box"))
    env.reset(seed=0)
    cfg = env.primitive_cfg
    before = env.object_pose()
    # A point on the table 1.1 m in front of the robot's base: the arm cannot get there.
    rows = _tick_through(env, make_primitive([0.6, 0.0, 0.41], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0],
                                             0, 1))
    assert rows[-1]["phase"] == IDLE and rows[-1]["count"] == 1 and rows[-1]["reached"] == 0
    assert PUSH not in [row["phase"] for row in rows]
    assert len(rows) == cfg.approach_steps + cfg.retreat_steps
    moved, turned = _object_moved(env, before)
    assert moved < 0.002 and turned < 0.02


def _bottom_primitive(env: PrimitiveEnv, obs: dict) -> dict:
    """A point on the object's underside, its normal pointing into the table: its pre-contact
    point (raised to min_tool_height above the table) lies inside the object."""
    normals = obs["normals"]
    bottom = np.flatnonzero(normals[:, 2] < -0.9)
    assert len(bottom) > 0
    return {"point": int(bottom[0]), "motion": np.array([1.0, 0.0, 0.0])}


def test_a_primitive_into_the_table_is_given_up_without_an_error():
    env = PrimitiveEnv(_config("box"), PrimitiveConfig(**AT_THE_POINT))
    obs, _ = env.reset(seed=0)
    cfg = env.primitive_cfg
    obs, reward, terminated, truncated, info = env.step(_bottom_primitive(env, obs))
    assert info["reached"] is False and "sim_error" not in info
    assert np.isfinite(reward) and not terminated and not truncated
    # Given up at once: only the retreat's ticks, no approach.
    assert info["ticks"] == cfg.retreat_steps
    assert _status(env)["phase"] == IDLE and _status(env)["count"] == 1
    # The env goes on: the next primitive, at a side point, is reached.
    index = _side_point(env, obs)
    _, _, _, _, info = env.step({"point": index, "motion": _inward(obs["normals"][index])})
    assert info["reached"] is True


def test_a_primitive_into_the_table_leaves_the_object_where_it_was():
    env = PrimitiveEnv(_config("box"))
    obs, _ = env.reset(seed=0)
    before = env.object_pose()
    env.step(_bottom_primitive(env, obs))
    moved, turned = _object_moved(env, before)
    assert moved < 0.005 and turned < 0.05, (moved, turned)


# ------------------------------------------------------------------------------- the policy

def _agent(seed: int = 0):
    from corn_drake.nn.encoders.encoder_files import make_policy_encoder
    from corn_drake.rl.primitive.agent import PrimitiveAgent

    torch.manual_seed(seed)
    return PrimitiveAgent(make_policy_encoder("corn")).eval()


def _step_until_count(env: PrimitiveEnv, count: int, max_ticks: int = 80) -> dict:
    """Steps the evaluation env period by period until the executor has started `count`
    primitives; returns the policy's observation at the tick that started the last one."""
    policy = env.handles.policy
    ctx = policy.GetMyContextFromRoot(env.context)
    for _ in range(max_ticks):
        seen = policy.observation(ctx)  # what the policy reads at the coming tick
        _, _, terminated, truncated, _ = env.step(None)
        if _status(env)["count"] >= count:
            assert _status(env)["count"] == count
            return seen
        assert not terminated and not truncated, "the episode ended before the primitive"
    raise AssertionError(f"no primitive {count} within {max_ticks} ticks")


def _choosing_by_an_outcome_model(agent, task):
    """The agent choosing by an outcome model of random weights (its output layer too)."""
    from corn_drake.rl.primitive.outcome.chooser import OutcomeChooser
    from corn_drake.rl.primitive.outcome.model import OutcomeModel

    model = OutcomeModel(38)
    torch.nn.init.normal_(model.net[-1].weight, std=0.1)
    agent.outcome_chooser, agent.task = OutcomeChooser(model.eval(), tokens=False), task
    return agent


@pytest.mark.parametrize("chooser, settle", [("critic", 0), ("outcome_model", 0),
                                             ("critic", 6)])
def test_the_reported_location_is_the_policys_own_choice(chooser, settle):
    agent = _agent()
    cfg = _config("box")
    if chooser == "outcome_model":
        agent = _choosing_by_an_outcome_model(agent, cfg.task)
    # Settling (a phase between the retreat and idle) must not shift the tick the next
    # primitive is taken at away from the tick the policy records its choice.
    agent.primitive_config = PrimitiveConfig(settle_steps=settle)
    env = PrimitiveEnv(cfg, agent.primitive_config, agent=agent)
    obs, _ = env.reset(seed=3)
    first = agent.choose(obs)  # the first primitive is chosen at the episode's first tick
    policy = env.handles.policy
    ctx = policy.GetMyContextFromRoot(env.context)
    for count in (1, 2):
        seen = _step_until_count(env, count)
        choice = agent.choose(seen)
        if count == 1:
            assert choice["point"] == first["point"]
        held = policy.GetOutputPort("choice").Eval(ctx)
        assert _status(env)["location"] == held[0] == choice["point"]
        assert held[1] == choice["location"]
        np.testing.assert_allclose(held[2:5], choice["motion"], atol=1e-6)
        np.testing.assert_allclose(policy.GetOutputPort("scores").Eval(ctx), choice["scores"],
                                   atol=1e-6)
        # The executor pushes from the pre-contact point of the chosen point (lowered for a
        # low side push, systems/control/low_push.py).
        pre = env.handles.executor.planner.pre_contact(*push_contact(
            seen["cloud"], seen["normals"], choice["point"], env.primitive_cfg))
        np.testing.assert_allclose(_status(env)["pre_contact"], pre, atol=1e-6)
        # Held while the primitive runs, though the policy would choose anew for the moved hand.
        env.step(None)
        np.testing.assert_array_equal(policy.GetOutputPort("choice").Eval(ctx), held)
        np.testing.assert_allclose(policy.GetOutputPort("scores").Eval(ctx), choice["scores"],
                                   atol=1e-6)


# ------------------------------------------------------------------------------- bad actions

@pytest.mark.parametrize("action, named", [
    ({"point": 512, "motion": [0.0, 0.0, 0.0]}, "'point'"),
    ({"point": -1, "motion": [0.0, 0.0, 0.0]}, "'point'"),
    ({"point": 3.0, "motion": [0.0, 0.0, 0.0]}, "'point'"),
    ({"point": np.arange(40), "motion": [0.0, 0.0, 0.0]}, "'point'"),
    ({"point": 3, "motion": [np.nan, 0.0, 0.0]}, "'motion'"),
    ({"point": 3, "motion": [0.0, np.inf, 0.0]}, "'motion'"),
    ({"point": 3, "motion": [0.0, 0.0]}, "'motion'"),
    ({"point": 3, "motion": np.zeros(60)}, "'motion'"),
    ({"point": 3, "motion": "up"}, "'motion'"),
    ({"point": 3}, "'motion'"),
    ({"point": 3, "motion": [0.0, 0.0, 0.0], "force": 1.0}, "'point'"),
    (np.zeros(4), "'point'"),
])
def test_bad_actions_are_refused_naming_the_key(action, named):
    env = PrimitiveEnv(_config("box"))
    env.reset(seed=0)
    steps, status = env._steps, env.executor_status()
    with pytest.raises(InputError, match=named) as error:
        env.step(action)
    assert "\n" not in str(error.value)
    # Refused before anything ran: no tick, no primitive.
    assert env._steps == steps and env.primitives == 0
    np.testing.assert_array_equal(env.executor_status(), status)


# ------------------------------------------------------------------------------- the view

def _animations(html: str, prefix: str) -> tuple[dict, dict, dict]:
    """({path: set_object}, {path: [(frame, visible)]}, {path: translation}) under `prefix`."""
    objects, tracks, places = {}, {}, {}
    for msg in meshcat_messages(html):
        path = msg.get("path", "")
        if msg["type"] == "set_object" and path.startswith(prefix):
            objects[path] = msg
        if msg["type"] == "set_transform" and path.startswith(prefix):
            places[path] = np.asarray(msg["matrix"], float)[12:15]  # column-major 4 x 4
        if msg["type"] == "set_animation":
            for anim in msg["animations"]:
                if anim["path"].startswith(prefix):
                    (track,) = anim["clip"]["tracks"]
                    assert (track["name"], track["type"]) == (".visible", "boolean")
                    tracks[anim["path"]] = [(k["time"], k["value"]) for k in track["keys"]]
    return objects, tracks, places


def test_the_view_draws_each_primitive_live_and_in_recordings(tmp_path):
    from corn_drake.viz.meshcat import save_recording

    agent = _agent(1)
    meshcat = Meshcat()
    env = PrimitiveEnv(_config("box"), meshcat=meshcat, agent=agent)
    view = env.diagram.GetSubsystemByName("primitive_view")
    policy = env.handles.policy
    ctx = policy.GetMyContextFromRoot(env.context)
    push_distance = env.primitive_cfg.push_distance
    env.reset(seed=4)
    meshcat.StartRecording(set_visualizations_while_recording=False)
    starts, drawn, count = [], {}, 0
    for step in range(1, 61):
        obs, _, terminated, truncated, _ = env.step(None)
        status = _status(env)
        if status["count"] > count:  # started at the previous boundary, drawn at this one
            count = int(status["count"])
            starts.append(env.clock.boundary(step - 1))
            drawn[count] = {"cloud": obs["cloud"].astype(float), "status": status,
                            "choice": policy.GetOutputPort("choice").Eval(ctx),
                            "scores": policy.GetOutputPort("scores").Eval(ctx)}
        if terminated or truncated:
            break
    meshcat.StopRecording()
    assert count >= 2, "the episode needs at least two primitives"
    html = save_recording(meshcat, tmp_path / "episode.html").read_text()
    objects, tracks, places = _animations(html, view.path)
    for k in range(1, count + 1):
        here = primitive_path(view.path, k)
        for part in ("contact", "arrow/head", "scores"):
            assert meshcat.HasPath(f"{here}/{part}") and f"{here}/{part}" in objects, (k, part)
        # Shown from its start to the next one's start, hidden before.
        keys = dict(tracks[here])
        frame = int(starts[k - 1] * FPS)
        assert keys[frame] is True
        if frame > 0:
            assert keys[0] is False
        if k < count:
            assert keys[int(starts[k] * FPS)] is False
        # Where it is drawn: the chosen cloud point, the push's end.
        d = drawn[k]
        np.testing.assert_allclose(places[f"{here}/contact"], d["cloud"][int(d["choice"][0])],
                                   atol=1e-5)
        end = d["status"]["pre_contact"] + np.clip(d["choice"][2:5], -1, 1) * push_distance
        np.testing.assert_allclose(places[f"{here}/arrow/head"], end, atol=1e-5)
    assert not meshcat.HasPath(primitive_path(view.path, count + 1))
    # The scores: each point coloured by its nearest patch centre's score, the centres being
    # the locations the policy scores, in its order.
    d = drawn[count]
    locations = nearest_locations(d["cloud"], len(d["scores"]))
    candidates = agent.choose({**obs, "cloud": d["cloud"].astype(np.float32)})["candidates"]
    np.testing.assert_array_equal(locations[candidates], np.arange(len(candidates)))
    per_point = d["scores"][locations]
    color = objects[f"{primitive_path(view.path, count)}/scores"]["object"]["geometries"][0][
        "data"]["attributes"]["color"]
    shown = np.frombuffer(color["array"].data, np.float32).reshape(-1, 3)
    np.testing.assert_allclose(shown, viridis_rgb(per_point - per_point.min()) / 255.0, atol=1e-6)
    assert len(np.unique(shown, axis=0)) > 1

    # A new episode starts clean: the earlier primitives are gone until drawn again.
    env.reset(seed=5)
    assert not meshcat.HasPath(primitive_path(view.path, 1))
    env.step(None)
    env.step(None)
    assert meshcat.HasPath(f"{primitive_path(view.path, 1)}/contact")
    assert not meshcat.HasPath(primitive_path(view.path, 2))


def test_the_view_without_a_policy_draws_the_sent_primitive():
    meshcat = Meshcat()
    env = PrimitiveEnv(_config("box"), meshcat=meshcat)
    view = env.diagram.GetSubsystemByName("primitive_view")
    obs, _ = env.reset(seed=0)
    index = _side_point(env, obs)
    motion = _inward(obs["normals"][index])
    _, _, _, _, info = env.step({"point": index, "motion": motion})
    here = primitive_path(view.path, 1)
    assert meshcat.HasPath(f"{here}/contact") and meshcat.HasPath(f"{here}/arrow/head")
    assert not meshcat.HasPath(f"{here}/scores")  # no policy, no scores
    _, _, places = _animations(meshcat.StaticHtml(), view.path)
    np.testing.assert_allclose(places[f"{here}/contact"], info["primitive"][:3], atol=1e-9)
    end = _status(env)["pre_contact"] + motion * env.primitive_cfg.push_distance
    np.testing.assert_allclose(places[f"{here}/arrow/head"], end, atol=1e-9)


def test_every_cloud_point_takes_one_of_the_patch_centres_as_its_location():
    cloud = np.random.default_rng(0).normal(size=(64, 3))
    patches = nearest_locations(cloud, 8)
    assert patches.shape == (64,) and set(patches.tolist()) == set(range(8))
    with pytest.raises(ValueError, match="num_locations"):
        nearest_locations(cloud, 64)
