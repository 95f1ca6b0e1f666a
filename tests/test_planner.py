"""The planning policy (rl/planner/): its env's snapshot / restore is exact for every primitive
kind, each kind reaches its pre-contact pose on a box and does what it is for (a topple puts
another face down, a turn turns more than it moves), the search spends the budget it says and
reuses the level it already simulated, and `evaluate --run planner` refuses what it cannot do."""

from __future__ import annotations

import numpy as np
import pytest

from corn_drake.config.diagram_files import load_primitive_env_config
from corn_drake.errors import InputError
from corn_drake.evaluation.planner_episodes import cloud_distance, wilson
from corn_drake.rl.planner.kinds import Candidate, goal_errors, propose
from corn_drake.rl.planner.search import (Node, Planner, PlannerConfig, PlannerEnv, beam_of,
                                          budget, planner_settings, primitive_config)
from corn_drake.systems.primitive_executor import reachable_from_above
from corn_drake.transforms import quat_wxyz_to_matrix


def _quat(R: np.ndarray) -> np.ndarray:
    from pydrake.math import RotationMatrix

    return RotationMatrix(R).ToQuaternion().wxyz()


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


@pytest.fixture(scope="module")
def env():
    # The full6d env's own object: a 9 x 7 x 5 cm box.
    return PlannerEnv(load_primitive_env_config("full6d"), primitive_config({}))


def _kind(env, obs, kind: str, goal) -> Candidate:
    cloud, normals = obs["cloud"].astype(float), obs["normals"].astype(float)
    reach = reachable_from_above(cloud[:, 2], normals[:, 2], env.primitive_cfg)
    found = [c for c in propose(cloud, normals, env.object_pose(), goal,
                                env.primitive_cfg.push_distance, reach, (kind,), 1)]
    assert found, f"no {kind} candidate on the box"
    return found[0]


def _turned_goal(pose, yaw=0.0, tip=0.0, shift=(0.0, 0.0)):
    R = quat_wxyz_to_matrix(pose[3:])
    goal = np.array(pose, float)
    goal[:2] += shift
    goal[3:] = _quat(_rz(yaw) @ _rx(tip) @ R)
    return goal


def test_a_snapshot_restore_round_trip_is_exact_for_an_exact_aim(env):
    obs, _ = env.reset(seed=2)
    topple = _kind(env, obs, "topple", _turned_goal(env.object_pose(), tip=np.pi / 2))
    start = env.snapshot()
    first = env.step_candidate(topple)
    after = (env.object_pose(), env.context.get_time(), env._steps, env.primitives)
    env.restore(start)
    env.step_candidate(_kind(env, obs, "push", _turned_goal(env.object_pose(),
                                                             shift=(0.1, 0.0))))
    env.restore(start)
    again = env.step_candidate(topple)
    for a, b in zip(after, (env.object_pose(), env.context.get_time(), env._steps,
                            env.primitives)):
        np.testing.assert_array_equal(a, b)
    assert again[1] == first[1]
    # The exact aim is the candidate's own point: the executor's pre-contact point sits off it.
    np.testing.assert_array_equal(again[4]["primitive"][:3], topple.point)


def test_a_topple_reaches_its_pre_contact_pose_and_puts_another_face_down(env):
    # Seed 0 stands the box on its 5 x 7 cm face, 9 cm tall: a horizontal push up high tips
    # it. (Lying flat, 5 cm tall, the same push slides it: mu * h < half its width. Tipping a
    # flat object needs the pivot, not built yet.)
    obs, _ = env.reset(seed=0)
    start = env.object_pose()
    up_before = quat_wxyz_to_matrix(start[3:])[:, 2]
    topple = _kind(env, obs, "topple", _turned_goal(start, tip=np.pi / 2))
    assert topple.point[2] > obs["cloud"][:, 2].mean(), "a topple touches above the centre"
    step = env.step_candidate(topple)
    assert step[4]["reached"]
    up_after = quat_wxyz_to_matrix(env.object_pose()[3:])[:, 2]
    assert np.arccos(np.clip(up_before @ up_after, -1, 1)) > 1.0, "the same face is still down"


def test_a_turn_reaches_its_pre_contact_pose_and_turns_more_than_it_moves(env):
    obs, _ = env.reset(seed=2)
    start, snapshot = env.object_pose(), env.snapshot()
    goal = _turned_goal(start, yaw=0.8)
    turn = _kind(env, obs, "turn", goal)
    step = env.step_candidate(turn)
    assert step[4]["reached"]
    end = env.object_pose()
    yaw = goal_errors(start, end)["yaw"]  # the turn done, with its sign
    moved = np.linalg.norm(end[:2] - start[:2])
    # Against a push through the centre of the same length from the same state: the turn must
    # turn the box (the right way, > 0.2 rad) and turn it per cm moved several times more.
    env.restore(snapshot)
    push = _kind(env, obs, "push", _turned_goal(start, shift=-turn.normal[:2] * 0.1))
    env.step_candidate(Candidate("push", push.index, push.point, push.normal,
                                 push.motion / np.abs(push.motion).max()
                                 * np.abs(turn.motion).max(), False))
    push_end = env.object_pose()
    push_yaw = abs(goal_errors(start, push_end)["yaw"])
    push_moved = np.linalg.norm(push_end[:2] - start[:2])
    assert push_moved > 0.01, "the reference push did not move the box"
    assert yaw > 0.2 and yaw / moved > 3 * push_yaw / push_moved, (yaw, moved, push_yaw,
                                                                   push_moved)


def test_a_push_reaches_its_pre_contact_pose_and_moves_toward_the_goal(env):
    obs, _ = env.reset(seed=2)
    start = env.object_pose()
    goal = _turned_goal(start, shift=(0.0, -0.1))
    step = env.step_candidate(_kind(env, obs, "push", goal))
    assert step[4]["reached"]
    assert np.linalg.norm(env.object_pose()[:2] - goal[:2]) < 0.07


def test_topples_are_offered_only_when_the_goal_has_another_face_down():
    # A cube's cloud: 6 faces of 5 x 5 points, normals outward; resting at the origin.
    g = np.linspace(-0.02, 0.02, 5)
    points, normals = [], []
    for axis in range(3):
        for sign in (-1, 1):
            for a in g:
                for b in g:
                    p = np.zeros(3)
                    p[axis], p[(axis + 1) % 3], p[(axis + 2) % 3] = sign * 0.025, a, b
                    n = np.zeros(3)
                    n[axis] = sign
                    points.append(p + [0.5, 0, 0.025])
                    normals.append(n)
    cloud, normals = np.array(points), np.array(normals)
    pose = np.array([0.5, 0, 0.025, 1, 0, 0, 0.0])
    reach = np.ones(len(cloud), bool)
    same_face = propose(cloud, normals, pose, _turned_goal(pose, yaw=0.5, shift=(0.1, 0)),
                        0.15, reach)
    assert {c.kind for c in same_face} == {"push", "turn"}
    tipped = propose(cloud, normals, pose, _turned_goal(pose, tip=np.pi / 2), 0.15, reach)
    topples = [c for c in tipped if c.kind == "topple"]
    assert topples and all(c.exact for c in topples)
    # Turned +90 deg about x: the body's +y side must come up, so the top goes toward -y.
    assert all(c.motion[1] < 0 and c.point[2] > 0.035 for c in topples)
    # A turn's push closes the yaw error: its torque about the centre has the error's sign.
    for sign in (1, -1):
        turn = [c for c in propose(cloud, normals, pose, _turned_goal(pose, yaw=sign * 0.5),
                                   0.15, reach, ("turn",))][0]
        r = turn.point[:2] - cloud[:, :2].mean(axis=0)
        assert np.sign(r[0] * turn.motion[1] - r[1] * turn.motion[0]) == sign
    with pytest.raises(InputError, match="unknown primitive kind"):
        propose(cloud, normals, pose, pose, 0.15, reach, ("pivot",))


def test_the_search_spends_its_budget_and_reuses_the_level_it_simulated(env):
    config = PlannerConfig(per_kind=1, beam=2, depth=2, kinds="push,turn")
    planner = Planner(config, env.primitive_cfg, env.cfg.task)
    env.reset(seed=2)
    planner.reset()
    first = planner.act(env)[4]["planner"]
    assert first["simulated"] == first["candidates"] * (1 + min(config.beam,
                                                                first["candidates"]))
    assert first["simulated"] <= budget(config) == 6
    second = planner.act(env)[4]["planner"]
    # Its first level was the chosen node's, already simulated: only the beam's children.
    assert 0 < second["simulated"] <= config.beam * 2
    depth_one = Planner(PlannerConfig(per_kind=1, depth=1, kinds="push,turn"),
                        env.primitive_cfg, env.cfg.task)
    env.reset(seed=2)
    depth_one.reset()
    decision = depth_one.act(env)[4]["planner"]
    assert decision["simulated"] == decision["candidates"] == 2


def test_the_beam_keeps_the_best_of_each_kind_first():
    def node(kind, score):
        return Node(Candidate(kind, 0, np.zeros(3), np.zeros(3), np.zeros(3), False), None,
                    None, score, False)

    nodes = [node("turn", -1), node("turn", -2), node("push", -5), node("turn", -3)]
    kept = beam_of(nodes, 2)
    assert [n.candidate.kind for n in kept] == ["turn", "push"]
    assert [n.score for n in beam_of(nodes, 3)] == [-1, -5, -2]


def test_planner_settings_are_checked_in_one_line():
    config, primitive, rest = planner_settings(["planner.beam=4", "primitive.push_height=0",
                                                "task.episode_steps=50"])
    assert config.beam == 4 and primitive == {"push_height": "0"}
    assert rest == ["task.episode_steps=50"]
    assert primitive_config(primitive).push_height == 0.0
    with pytest.raises(InputError, match="no setting 'width'"):
        planner_settings(["planner.width=3"])
    with pytest.raises(InputError, match="planner.beam"):
        planner_settings(["planner.beam=0"])
    with pytest.raises(InputError, match="planner.kinds"):
        planner_settings(["planner.kinds=push,pivot"])
    with pytest.raises(InputError, match="no such setting"):
        primitive_config({"speed": "1"})


def test_wilson_interval_and_the_cloud_distance():
    low, high = wilson(15, 20)
    assert 0.53 < low < 0.54 and 0.88 < high < 0.89
    assert wilson(0, 0) is None
    pose = np.array([0.5, 0, 0.1, 1, 0, 0, 0.0])
    cloud = np.array([[0.5, 0.05, 0.1], [0.5, -0.05, 0.1]])
    assert cloud_distance(cloud, pose, pose) == 0.0
    shifted = pose.copy()
    shifted[0] += 0.02
    assert np.isclose(cloud_distance(cloud, pose, shifted), 0.02)
    flipped = pose.copy()
    flipped[3:] = [0, 0, 0, 1.0]  # half a turn about z: both points move 10 cm
    assert np.isclose(cloud_distance(cloud, pose, flipped), 0.1)


def test_evaluate_refuses_episodes_from_for_a_learned_policy(tmp_path, capsys):
    from corn_drake.cli import main

    code = main(["evaluate", "--run", "scripted", "--episodes-from", "3", "--episodes", "5",
                 "--report", str(tmp_path / "r.json")])
    assert code != 0
    assert "--episodes-from applies to --run planner" in capsys.readouterr().err


def test_evaluate_runs_the_planner_reports_its_cost_and_resumes(tmp_path, capsys):
    """`evaluate --run planner` end to end on a two-object library at the smallest budget: the
    report says it is privileged, what each decision simulated and cost, a failure per episode;
    a rerun of the same command resumes from the rows file instead of playing again."""
    import json

    from corn_drake.cli import main
    from tests.fixtures import write_loadable_library

    library = write_loadable_library(tmp_path / "lib", 1, 1)
    report = tmp_path / "r.json"
    argv = ["evaluate", "--run", "planner", "--objects", str(library), "--split", "unseen",
            "--episodes", "1", "--no-progress", "--set", "planner.per_kind=1", "--set",
            "planner.depth=1", "--set", "primitive.max_primitives=2", "--report", str(report)]
    assert main([*argv, "--record", "1"]) == 2  # no recordings yet: said, not skipped silently
    assert "--record 0" in capsys.readouterr().err and not report.exists()
    assert main([*argv, "--record", "0"]) == 0
    first = json.loads(report.read_text())
    assert first["privileged"] is True and first["episodes"][0]["failure"]
    assert 1 <= first["simulated_per_decision"] <= first["budget_per_decision"] == 3
    assert first["cpu_seconds_per_decision"] > 0
    rows = report.with_suffix(".rows.jsonl")
    before = rows.read_text()
    assert main([*argv, "--record", "0"]) == 0
    assert rows.read_text() == before  # nothing played again
    assert json.loads(report.read_text())["episodes"] == first["episodes"]


def test_split_runs_merge_into_one_report_and_bad_parts_are_refused(tmp_path, capsys):
    import json

    from corn_drake.cli import main
    from tests.fixtures import write_loadable_library

    library = write_loadable_library(tmp_path / "lib", 1, 1)
    common = ["evaluate", "--run", "planner", "--objects", str(library), "--split", "all",
              "--record", "0", "--no-progress", "--set", "planner.per_kind=1", "--set",
              "planner.depth=1", "--set", "primitive.max_primitives=1"]
    assert main([*common, "--episodes", "1", "--report", str(tmp_path / "a.json")]) == 0
    assert main([*common, "--episodes-from", "1", "--episodes", "2",
                 "--report", str(tmp_path / "b.json")]) == 0
    a, b = tmp_path / "a.rows.jsonl", tmp_path / "b.rows.jsonl"
    # A kill mid-append leaves half a line: the rows before it are whole and still merge.
    with open(b, "a") as f:
        f.write('{"episode": 7, "obj')
    assert main(["merge-reports", str(a), str(b), "--report", str(tmp_path / "all.json")]) == 0
    merged = json.loads((tmp_path / "all.json").read_text())
    parts = [json.loads((tmp_path / n).read_text())["episodes"][0] for n in ("a.json", "b.json")]
    assert merged["episodes"] == parts and merged["complete"] and merged["privileged"]
    assert [r["object"] for r in parts] == [o for o in json.loads(
        a.read_text().splitlines()[0])["settings"]["objects"]]  # episode k on object k
    capsys.readouterr()
    assert main(["merge-reports", str(a), str(a), "--report", str(tmp_path / "x.json")]) == 2
    assert "episode 0 is in both" in capsys.readouterr().err
    other = tmp_path / "other.rows.jsonl"
    lines = b.read_text().splitlines()
    settings = json.loads(lines[0])
    settings["settings"]["planner"]["per_kind"] = 5
    other.write_text("\n".join([json.dumps(settings), *lines[1:]]) + "\n")
    assert main(["merge-reports", str(a), str(other), "--report", str(tmp_path / "x.json")]) == 2
    assert "settings differ" in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()
