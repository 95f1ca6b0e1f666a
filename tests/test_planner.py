"""The 6D expert (rl/planner/): the env's snapshot / restore is exact for an exactly aimed
primitive, each analytic kind reaches its pre-contact pose on a box and does what it is for (a
topple puts another face down, a turn turns more than it moves), the search values a first
primitive by r1 + discount x max r2 over a beam and spends the budget it says, its settings go
through the common --set path, and `evaluate --run planner` reports, labels, resumes and
refuses what it cannot do."""

from __future__ import annotations

import numpy as np
import pytest

from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
from corn_drake.errors import InputError
from corn_drake.evaluation.episode_rows import wilson
from corn_drake.evaluation.planner_play import cloud_distance
from corn_drake.config.planner import PlannerConfig, PlannerRunConfig
from corn_drake.rl.envs.branching import Candidate
from corn_drake.rl.envs.primitive_env import PrimitiveEnv
from corn_drake.storage.gz_lines import read_lines
from corn_drake.rl.planner.kinds import goal_errors, propose
from corn_drake.rl.planner.search import Planner, budget
from corn_drake.systems.control.primitive_executor import reachable_from_above
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
    return PrimitiveEnv(load_primitive_env_config("full6d"), PlannerRunConfig().primitive)


def _step(env, candidate: Candidate):
    return env.step(candidate.action(), aim=candidate.aim)


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
    first = _step(env, topple)
    after = (env.object_pose(), env.context.get_time(), env.steps, env.primitives)
    env.restore(start)
    _step(env, _kind(env, obs, "push", _turned_goal(env.object_pose(),
                                                             shift=(0.1, 0.0))))
    env.restore(start)
    again = _step(env, topple)
    for a, b in zip(after, (env.object_pose(), env.context.get_time(), env.steps,
                            env.primitives)):
        np.testing.assert_array_equal(a, b)
    assert again[1] == first[1]
    # The exact aim is the candidate's own point: the executor's pre-contact point sits off it.
    np.testing.assert_array_equal(again[4]["primitive"][:3], topple.aim[0])


def test_a_topple_reaches_its_pre_contact_pose_and_puts_another_face_down(env):
    # Seed 0 stands the box on its 5 x 7 cm face, 9 cm tall: a horizontal push up high tips
    # it. (Lying flat, 5 cm tall, the same push slides it: mu * h < half its width. Tipping a
    # flat object needs the pivot, not built yet.)
    obs, _ = env.reset(seed=0)
    start = env.object_pose()
    up_before = quat_wxyz_to_matrix(start[3:])[:, 2]
    topple = _kind(env, obs, "topple", _turned_goal(start, tip=np.pi / 2))
    assert topple.aim[0][2] > obs["cloud"][:, 2].mean(), "a topple touches above the centre"
    step = _step(env, topple)
    assert step[4]["reached"]
    up_after = quat_wxyz_to_matrix(env.object_pose()[3:])[:, 2]
    assert np.arccos(np.clip(up_before @ up_after, -1, 1)) > 1.0, "the same face is still down"


def test_a_turn_reaches_its_pre_contact_pose_and_turns_more_than_it_moves(env):
    obs, _ = env.reset(seed=2)
    start, snapshot = env.object_pose(), env.snapshot()
    goal = _turned_goal(start, yaw=0.8)
    turn = _kind(env, obs, "turn", goal)
    step = _step(env, turn)
    assert step[4]["reached"]
    end = env.object_pose()
    yaw = goal_errors(start, end)["yaw"]  # the turn done, with its sign
    moved = np.linalg.norm(end[:2] - start[:2])
    # Against a push through the centre of the same length from the same state: the turn must
    # turn the box (the right way, > 0.2 rad) and turn it per cm moved several times more.
    env.restore(snapshot)
    normal = obs["normals"][turn.point] / np.linalg.norm(obs["normals"][turn.point])
    push = _kind(env, obs, "push", _turned_goal(start, shift=-normal[:2] * 0.1))
    _step(env, Candidate("push", push.point, push.motion / np.abs(push.motion).max()
                         * np.abs(turn.motion).max()))
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
    step = _step(env, _kind(env, obs, "push", goal))
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
    assert {c.source for c in same_face} == {"push", "turn"}
    assert all(c.aim is None for c in same_face)  # aimed as every shipped push: lowered
    tipped = propose(cloud, normals, pose, _turned_goal(pose, tip=np.pi / 2), 0.15, reach)
    topples = [c for c in tipped if c.source == "topple"]
    assert topples and all(c.aim is not None for c in topples)
    # Turned +90 deg about x: the body's +y side must come up, so the top goes toward -y.
    assert all(c.motion[1] < 0 and c.aim[0][2] > 0.035 for c in topples)
    # A turn's push closes the yaw error: its torque about the centre has the error's sign.
    for sign in (1, -1):
        turn = [c for c in propose(cloud, normals, pose, _turned_goal(pose, yaw=sign * 0.5),
                                   0.15, reach, ("turn",))][0]
        r = cloud[turn.point, :2] - cloud[:, :2].mean(axis=0)
        assert np.sign(r[0] * turn.motion[1] - r[1] * turn.motion[0]) == sign
    with pytest.raises(InputError, match="unknown primitive kind"):
        propose(cloud, normals, pose, pose, 0.15, reach, ("pivot",))


class _TreeEnv:
    """A stand-in env for the search alone: its state is the sequence of points chosen so far,
    a primitive's reward is REWARDS[state + (point,)] (0 where unlisted), and a point 9 ends
    the episode. Snapshots are the state itself."""

    REWARDS = {(0,): 1.0, (1,): 0.9, (2,): 0.5, (3,): 0.1,
               (0, 0): -1.0, (0, 1): -2.0, (1, 2): 3.0, (2, 0): 9.0}

    def __init__(self):
        self.state = ()

    def snapshot(self):
        return self.state

    def restore(self, snapshot):
        self.state = snapshot

    def step(self, action, aim=None):
        self.state = self.state + (action["point"],)
        done = action["point"] == 9
        return ({"state": self.state}, self.REWARDS.get(self.state, 0.0), done, False,
                {"status": {"success": 0.0}})

    def object_pose(self):
        return np.zeros(7)

    def object_still(self):
        return True


def _tree_source(points):
    def propose(env, obs, rng):
        rng.uniform()  # a draw per expansion, as the policy source's random motions
        return [Candidate("policy", p, np.zeros(3)) for p in points]
    return propose


def test_the_search_values_a_first_primitive_by_r1_plus_discounted_best_r2_over_its_beam():
    env = _TreeEnv()
    # Depth 1: the most reward now (point 0).
    one = Planner(PlannerConfig(depth=1), [_tree_source([0, 1, 2, 3])])
    one.reset(0)
    one.act(env, {})
    assert env.state == (0,) and one.decisions[0]["simulated"] == 4
    # Depth 2, beam 2: points 0 and 1 are valued (2 is outside the beam, though 0.5 + 0.9 x 9
    # would win): 0 -> 1.0 + 0.9 x max(-1, -2, 0, 0) = 1.0, 1 -> 0.9 + 0.9 x 3 = 3.6.
    env.restore(())
    two = Planner(PlannerConfig(depth=2, beam=2, discount=0.9), [_tree_source([0, 1, 2, 3])])
    two.reset(0)
    two.act(env, {})
    decision = two.decisions[0]
    assert env.state == (1,) and np.isclose(decision["value"], 0.9 + 0.9 * 3.0)
    assert decision["simulated"] == 4 + 2 * 4 == budget(two.config, 4)
    values = [label[-1] for label in decision["labels"]]
    assert values[2:] == [None, None] and np.isclose(values[0], 1.0)
    # Beam 3 reaches point 2's continuation.
    env.restore(())
    wide = Planner(PlannerConfig(depth=2, beam=3), [_tree_source([0, 1, 2, 3])])
    wide.reset(0)
    wide.act(env, {})
    assert env.state == (2,) and wide.decisions[0]["simulated"] == 4 + 3 * 4


def test_an_ended_branch_is_valued_by_its_reward_alone_and_the_draws_follow_the_seed():
    env = _TreeEnv()
    env.REWARDS = {**_TreeEnv.REWARDS, (9,): 1.5}
    planner = Planner(PlannerConfig(depth=2, beam=4), [_tree_source([9, 1])])
    planner.reset(0)
    planner.act(env, {})
    # 9 ends the episode: valued 1.5, not expanded; 1 -> 0.9 + 0.9 x 0 = 0.9.
    assert env.state == (9,) and planner.decisions[0]["simulated"] == 2 + 2
    draws = []
    for _ in range(2):
        planner.reset(7)
        draws.append(planner.rng.uniform())
    assert draws[0] == draws[1] and draws[0] != np.random.default_rng(8).uniform()


def test_a_state_with_no_candidate_ends_its_branch_and_a_root_with_none_is_named():
    env = _TreeEnv()
    # Point 1 leads to a state with nothing to propose: valued by its reward alone (0.9).
    def source(env, obs, rng):
        return [] if env.state == (1,) else [Candidate("push", p, np.zeros(3)) for p in (0, 1)]
    planner = Planner(PlannerConfig(depth=2, beam=2), [source])
    planner.reset(0)
    planner.act(env, {})
    # 0 -> 1.0 + 0.9 x max(-1, -2) = 0.1; 1 -> 0.9 (nothing below it).
    assert env.state == (1,) and np.isclose(planner.decisions[0]["value"], 0.9)
    env.restore((1,))
    with pytest.raises(InputError, match="no candidate primitive at this state"):
        planner.act(env, {})


def test_planner_settings_go_through_the_common_set_path_in_one_line():
    from corn_drake.rl.runs.kinds import load_any_run

    loaded = load_any_run("planner")
    run_cfg, changes = loaded.configure(None, ["planner.beam=3", "primitive.push_height=0",
                                               "task.episode_steps=50",
                                               "planner.sources=[policy, turn]"])
    assert run_cfg.planner.beam == 3 and run_cfg.primitive.push_height == 0.0
    assert run_cfg.env.task.episode_steps == 50
    assert loaded.agent.config.sources == ["policy", "turn"]
    assert {c.key for c in changes} == {"planner.beam", "primitive.push_height",
                                        "env.task.episode_steps", "planner.sources"}
    for sets, message in ((["planner.width=3"], "did you mean"),
                          (["planner.beam=0"], "planner.beam must be"),
                          (["planner.sources=[policy, pivot]"], "planner.sources must be"),
                          (["planner.sources=[]"], "planner.sources must be non-empty"),
                          (["planner.policy="], "planner.policy must be a run folder"),
                          (["primitive.speed=1"], "unknown key"),
                          (["ppo.lr=1"], "unknown key .ppo.; the run config has env, primitive, planner")):
        with pytest.raises(InputError, match=message):
            load_any_run("planner").configure(None, sets)


def test_every_named_source_is_registered_and_a_bad_policy_run_is_named():
    from corn_drake.config.choices import PLANNER_SOURCES
    from corn_drake.rl.planner.kinds import KINDS
    from corn_drake.rl.planner.sources import SOURCES, load_policy

    assert tuple(SOURCES) == PLANNER_SOURCES and set(KINDS) < set(SOURCES)
    with pytest.raises(InputError, match="planner.policy: no run folder"):
        load_policy("runs/nothing_here", None, None)
    with pytest.raises(InputError, match="planner.policy: models/weights/push_state is a"):
        load_policy("models/weights/push_state", None, None)


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


def test_episodes_from_past_the_last_episode_is_refused_for_every_kind(tmp_path, capsys):
    # --episodes-from is every evaluation's now (tests/test_episode_core.py); a range with no
    # episode in it is refused before any file is written.
    from corn_drake.cli import main

    code = main(["evaluate", "--run", "scripted", "--episodes-from", "5", "--episodes", "5",
                 "--record", "0", "--report", str(tmp_path / "r.json")])
    assert code == 2
    assert "no episodes in [5, 5)" in capsys.readouterr().err
    assert not (tmp_path / "r.json").exists() and not (tmp_path / "r.rows.jsonl").exists()


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
            "--episodes", "1", "--no-progress", "--set", "planner.sources=[push, turn]",
            "--set", "planner.per_kind=1", "--set", "planner.depth=1", "--set",
            "primitive.max_primitives=2", "--report", str(report)]
    assert main([*argv, "--record", "1"]) == 2  # no recordings yet: said, not skipped silently
    assert "--record 0" in capsys.readouterr().err and not report.exists()
    assert main([*argv, "--record", "0"]) == 0
    first = json.loads(report.read_text())
    assert first["privileged"] is True and first["episodes"][0]["failure"]
    assert 1 <= first["simulated_per_decision"] <= first["budget_per_decision"] == 2
    assert first["cpu_seconds_per_decision"] > 0 and first["decisions_per_core_hour"] > 0
    # The labels: a header naming the columns, then one line per episode, a table per decision
    # whose rows are the root candidates (the chosen one among them).
    labels = read_lines(report.with_name("r.labels.jsonl.gz"))[0]
    header, episode = json.loads(labels[0]), json.loads(labels[1])
    assert header["columns"][-2:] == ["reward", "value"] and len(labels) == 2
    assert episode["seed"] == first["episodes"][0]["seed"]
    assert len(episode["decisions"]) == first["episodes"][0]["primitives"]
    for decision, made in zip(episode["decisions"], first["episodes"][0]["decisions"]):
        assert len(decision["labels"]) == made["candidates"]
        assert decision["labels"][decision["chosen"]][0] == made["source"]
    # Replayed from its seed with the executed primitives, the episode lands on the labelled
    # states: on this machine every executed primitive earns what it earned in the search.
    from corn_drake.assets.library import load_object_spec
    from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
    from corn_drake.rl.planner.labels import read_labels, replay

    settings, columns, records = read_labels(report.with_name("r.labels.jsonl.gz"))
    env_cfg = load_primitive_env_config(settings["task"])
    env_cfg.seed = settings["seed"]
    env = PrimitiveEnv(env_cfg, PlannerRunConfig().primitive.__class__(**settings["primitive"]),
                       load_object_spec(library, records[0]["object"]))
    replayed = list(replay(env, records[0], columns))
    assert len(replayed) == len(records[0]["decisions"])
    assert all(gap <= 1e-5 for _, _, gap in replayed)  # the labels keep 5 decimals
    assert replayed[0][0]["cloud"].shape == (512, 3)
    rows = report.with_suffix(".rows.jsonl")
    before = rows.read_text()
    assert main([*argv, "--record", "0"]) == 0
    assert rows.read_text() == before  # nothing played again
    assert json.loads(report.read_text())["episodes"] == first["episodes"]


def test_split_runs_merge_into_one_report_and_bad_parts_are_refused(tmp_path, capsys):
    import gzip
    import json

    from corn_drake.cli import main
    from tests.fixtures import write_loadable_library

    library = write_loadable_library(tmp_path / "lib", 1, 1)
    common = ["evaluate", "--run", "planner", "--objects", str(library), "--split", "all",
              "--record", "0", "--no-progress", "--set", "planner.sources=[push, turn]",
              "--set", "planner.per_kind=1", "--set", "planner.depth=1", "--set",
              "primitive.max_primitives=1"]
    assert main([*common, "--episodes", "1", "--report", str(tmp_path / "a.json")]) == 0
    assert main([*common, "--episodes-from", "1", "--episodes", "2",
                 "--report", str(tmp_path / "b.json")]) == 0
    a, b = tmp_path / "a.rows.jsonl", tmp_path / "b.rows.jsonl"
    # A part from before the labels were gzipped keeps them plain: it merges the same.
    plain = tmp_path / "a.labels.jsonl"
    plain.write_text("\n".join(read_lines(tmp_path / "a.labels.jsonl.gz")[0]) + "\n")
    (tmp_path / "a.labels.jsonl.gz").unlink()
    # A kill mid-append leaves half a line: the rows before it are whole and still merge.
    with open(b, "a") as f:
        f.write('{"episode": 7, "obj')
    assert main(["merge-reports", str(a), str(b), "--report", str(tmp_path / "all.json")]) == 0
    merged = json.loads((tmp_path / "all.json").read_text())
    # Their labels join too: one line per merged episode after the header.
    labels = read_lines(tmp_path / "all.labels.jsonl.gz")[0]
    assert [json.loads(line)["episode"] for line in labels[1:]] == [0, 1]
    plain.with_name("a.labels.jsonl.gz").write_bytes(gzip.compress(plain.read_bytes()))
    plain.unlink()  # gzipped by hand: one member holding every line reads the same
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
    # An evaluation into a report whose labels file is another evaluation's is refused before
    # it plays, and the file is left as it was.
    foreign = (tmp_path / "a.labels.jsonl.gz").read_bytes()
    (tmp_path / "c.labels.jsonl.gz").write_bytes(foreign)
    assert main([*common, "--set", "planner.per_kind=2", "--episodes", "1",
                 "--report", str(tmp_path / "c.json")]) == 2
    assert "another evaluation's labels" in capsys.readouterr().err
    assert (tmp_path / "c.labels.jsonl.gz").read_bytes() == foreign
    assert not (tmp_path / "c.rows.jsonl").exists()
