"""Task specs and samplers (corn_drake/tasks/): every variant's draws meet its ranges, ranges
that cannot be met raise naming the task and the ranges, and the overlays in diagrams/tasks/
load with their tags and restate no default."""

import numpy as np
import pytest
import yaml

from corn_drake import DIAGRAMS_DIR
from corn_drake.config.task import TaskConfig
from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.config.plumbing.loader import load_config
from corn_drake.errors import InputError
from corn_drake.config.plumbing.overrides import apply_sets, config_changes
from corn_drake.config.plumbing.diagram_files import available_tasks, load_teacher_config
from corn_drake.scene.objects import box_spec
from corn_drake.tasks.sampling import TABLE_MARGIN, sample_object_and_goal, sample_robot_joints
from corn_drake.config.task import Full6dGoal, PlanarGoal, PushFromHandGoal
from corn_drake.transforms import quat_wxyz_to_matrix

SPEC = box_spec([0.09, 0.07, 0.05], 0.3)
TABLE = [0.4, 0.5, 0.4]
HAND = np.array([-0.02, 0.03])
DRAWS = 200


def _draws(task: TaskConfig, thin: bool = False, hand=HAND, n: int = DRAWS):
    rng = np.random.default_rng(0)
    return [sample_object_and_goal(task, SPEC.stable_poses, SPEC.radius, thin, TABLE, hand, rng)
            for _ in range(n)]


def _rotation(pose):
    q = pose[3:]
    assert abs(np.linalg.norm(q) - 1) < 1e-9
    return quat_wxyz_to_matrix(q)


def _in_goal_region(task, xy):
    return task.goal_x[0] <= xy[0] <= task.goal_x[1] and task.goal_y[0] <= xy[1] <= task.goal_y[1]


def _yaw_between(Ra, Rb):
    return np.arccos(np.clip((np.trace(Rb @ Ra.T) - 1) / 2, -1, 1))


def _on_table(start):
    half = np.array(TABLE[:2]) / 2 * TABLE_MARGIN - SPEC.radius
    # The stable pose's own xy offset from its frame origin is small for a box.
    return np.all(np.abs(start[:2]) <= half + 1e-3)


def _stable_heights():
    return set(np.round(SPEC.stable_poses[:, 2], 9))


def test_full6d_draws_meet_the_paper_ranges():
    task = TaskConfig()
    g = task.goal
    assert isinstance(g, Full6dGoal)
    faces = set()
    for start, goal in _draws(task):
        assert np.linalg.norm(start[:2] - HAND) >= g.object_min_distance_to_hand
        assert np.linalg.norm(goal[:2] - start[:2]) >= g.min_goal_distance
        assert _in_goal_region(task, goal[:2]) and _on_table(start)
        assert {round(start[2], 9), round(goal[2], 9)} <= _stable_heights()
        _rotation(start)
        faces.add(round(goal[2], 6))
    assert len(faces) > 1  # goals come in more than one stable pose


def test_full6d_gives_thin_objects_only_yaw_goals():
    for start, goal in _draws(TaskConfig(), thin=True, n=50):
        # Same face down: world z maps to the same object-frame direction.
        np.testing.assert_allclose(_rotation(start).T @ [0, 0, 1], _rotation(goal).T @ [0, 0, 1],
                                   atol=1e-9)
        assert goal[2] == pytest.approx(start[2])


def test_planar_draws_keep_the_face_and_meet_distance_and_yaw():
    task = TaskConfig(goal=PlanarGoal(distance=[0.1, 0.15], max_yaw=0.5))
    for start, goal in _draws(task):
        assert np.linalg.norm(start[:2] - HAND) >= task.goal.object_min_distance_to_hand
        assert 0.1 - 1e-9 <= np.linalg.norm(goal[:2] - start[:2]) <= 0.15 + 1e-9
        assert goal[2] == pytest.approx(start[2]) and _in_goal_region(task, goal[:2])
        R0, Rg = _rotation(start), _rotation(goal)
        np.testing.assert_allclose(R0.T @ [0, 0, 1], Rg.T @ [0, 0, 1], atol=1e-9)
        assert _yaw_between(R0, Rg) <= 0.5 + 1e-9


def test_push_draws_put_the_goal_beyond_the_object_as_seen_from_the_hand():
    task = TaskConfig(goal=PushFromHandGoal(max_yaw=0.3), goal_x=[-0.18, 0.18],
                      goal_y=[-0.22, 0.22])
    g = task.goal
    hand = np.array([0.0, 0.0])
    turned = 0
    for start, goal in _draws(task, hand=hand):
        away, push = start[:2] - hand, goal[:2] - start[:2]
        assert g.object_distance_to_hand[0] - 1e-9 <= np.linalg.norm(away) <= g.object_distance_to_hand[1] + 1e-9
        assert g.distance[0] - 1e-9 <= np.linalg.norm(push) <= g.distance[1] + 1e-9
        cosine = away @ push / np.linalg.norm(away) / np.linalg.norm(push)
        assert np.arccos(np.clip(cosine, -1, 1)) <= g.heading_spread + 1e-9
        assert _in_goal_region(task, goal[:2]) and goal[2] == pytest.approx(start[2])
        yaw = _yaw_between(_rotation(start), _rotation(goal))
        assert yaw <= 0.3 + 1e-9
        turned += yaw > 1e-3
    assert turned > DRAWS // 2  # max_yaw is used, not ignored


def test_a_seed_gives_the_same_draws():
    task = TaskConfig(goal=PlanarGoal())
    a, b = _draws(task, n=5), _draws(task, n=5)
    for (sa, ga), (sb, gb) in zip(a, b):
        np.testing.assert_array_equal(sa, sb)
        np.testing.assert_array_equal(ga, gb)


@pytest.mark.parametrize("task, named", [
    (TaskConfig(name="far", goal=Full6dGoal(min_goal_distance=1.0)),
     r"task 'far': no goal in 1000 draws with task\.goal\.min_goal_distance 1\.0 m"),
    (TaskConfig(name="crowded", goal=Full6dGoal(object_min_distance_to_hand=2.0)),
     r"task 'crowded': no object start .*object_min_distance_to_hand 2\.0 m"),
    # Inside the workspace (a region outside it is refused by TaskConfig.check, before any
    # draw), but out of reach of every start: the sampler names the ranges.
    (TaskConfig(name="offside", goal=PlanarGoal(), goal_x=[0.45, 0.49], goal_y=[0.45, 0.54]),
     r"task 'offside': no goal .*task\.goal\.distance \[0\.1, 0\.2\].*task\.goal_x \[0\.45, 0\.49\]"),
    (TaskConfig(name="unreachable", goal=PushFromHandGoal(object_distance_to_hand=[0.5, 0.6])),
     r"task 'unreachable': no object/goal pair .*object_distance_to_hand \[0\.5, 0\.6\]"),
])
def test_ranges_that_cannot_be_met_raise_naming_the_task_and_ranges(task, named):
    with pytest.raises(InputError, match=named):
        _draws(task, n=1)


@pytest.mark.parametrize("task, named", [
    (TaskConfig(goal=PlanarGoal(distance=[0.2, 0.1])), r"task\.goal\.distance"),
    (TaskConfig(goal=PushFromHandGoal(heading_spread=-0.1)), r"task\.goal\.heading_spread"),
    (TaskConfig(goal_y=[0.2]), r"task\.goal_y"),
])
def test_malformed_ranges_are_named(task, named):
    with pytest.raises(InputError, match=named):
        _draws(task, n=1)


def test_robot_joints_stay_in_the_ranges_plus_noise():
    task = TaskConfig(robot_init_noise=0.0)
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = sample_robot_joints(task, rng)
        assert np.all(q >= np.array(task.robot_init_low) - 1e-12)
        assert np.all(q <= np.array(task.robot_init_high) + 1e-12)


def test_goal_variant_is_chosen_by_its_yaml_tag():
    cfg = load_config(TeacherDiagramConfig, text="task:\n  goal: !PlanarGoal {distance: [0.1, 0.15]}\n")
    assert cfg.task.goal == PlanarGoal(distance=[0.1, 0.15])
    assert isinstance(load_config(TeacherDiagramConfig, text="task: {name: x}").task.goal,
                      Full6dGoal)
    with pytest.raises(InputError, match="SpiralGoal"):
        load_config(TeacherDiagramConfig, text="task:\n  goal: !SpiralGoal {}\n")
    # A field of another variant is refused, not ignored.
    with pytest.raises(InputError, match="heading_spread"):
        load_config(TeacherDiagramConfig, text="task:\n  goal: !PlanarGoal {heading_spread: 0.5}\n")


class _TagLoader(yaml.SafeLoader):
    """Reads a YAML tag `!Name {...}` as {"!": "Name", ...} so overlays can be compared."""


_TagLoader.add_multi_constructor("!", lambda loader, suffix, node: {
    "!": suffix, **loader.construct_mapping(node, deep=True)})


def _restated_defaults(overlay, default, path=""):
    """Dotted keys of `overlay` (a plain dict) whose value equals the one in `default`."""
    found = []
    for key, value in overlay.items():
        if key == "!":
            continue
        name = f"{path}.{key}" if path else key
        current = getattr(default, key)
        if isinstance(value, dict):
            if "!" in value and value["!"] != type(current).__name__:
                # Another variant: compare its fields with that variant's defaults.
                current = {c.__name__: c for c in (Full6dGoal, PlanarGoal, PushFromHandGoal)}[value["!"]]()
            found += _restated_defaults(value, current, name)
        elif value == current or (isinstance(current, list) and list(value) == current):
            found.append(name)
    return found


@pytest.mark.parametrize("name", ["full6d", "planar", "planar_near", "push"])
def test_task_overlays_name_their_task_and_only_what_differs(name):
    path = DIAGRAMS_DIR / "tasks" / f"{name}.yaml"
    cfg = load_config(TeacherDiagramConfig, path)  # on its own: the missing keys are defaults
    assert cfg.task.name == name and load_teacher_config(name).task.name == name
    overlay = yaml.load(path.read_text(), Loader=_TagLoader)
    restated = [k for k in _restated_defaults(overlay, TeacherDiagramConfig()) if k != "task.name"
                or name != "full6d"]
    assert restated == []


def test_task_overlays_choose_their_goal_variant():
    goals = {n: type(load_teacher_config(n).task.goal) for n in available_tasks()}
    assert goals == {"full6d": Full6dGoal, "planar": PlanarGoal, "planar_near": PlanarGoal,
                     "push": PushFromHandGoal, "push_turn": PushFromHandGoal}
    push = load_teacher_config("push")
    assert not push.task.check_orientation and push.controller.max_position_delta == 0.03
    # Every overlay is listed in the folder's README.
    readme = (DIAGRAMS_DIR / "tasks" / "README.md").read_text()
    for path in (DIAGRAMS_DIR / "tasks").glob("*.yaml"):
        assert f"`{path.name}`" in readme


def test_a_tagged_config_round_trips_through_yaml_dump():
    from pydrake.common.yaml import yaml_dump_typed

    from corn_drake.config.plumbing.yaml_io import config_fields

    cfg = load_teacher_config("push")
    again = load_config(TeacherDiagramConfig, text=yaml_dump_typed(cfg))
    assert config_fields(again) == config_fields(cfg)
    assert again.task.goal == cfg.task.goal and type(again.task.goal) is PushFromHandGoal


def test_a_bad_value_inside_a_tagged_goal_is_named():
    with pytest.raises(InputError, match=r"task\.goal\.distance = \['a', 'b'\]"):
        load_config(TeacherDiagramConfig, text="task:\n  goal: !PlanarGoal {distance: [a, b]}\n")
    with pytest.raises(InputError, match=r"task\.goal\.heading_spread = 'wide'"):
        load_config(TeacherDiagramConfig, text="task:\n  goal: !PushFromHandGoal {heading_spread: wide}\n")


def test_set_changes_a_field_of_the_task_goal_variant_or_the_variant():
    from corn_drake.config.training import TrainConfig

    push = TrainConfig(env=load_teacher_config("push"))
    wider = apply_sets(push, ["task.goal.distance=[0.05, 0.1]"])
    assert wider.env.task.goal == PushFromHandGoal(distance=[0.05, 0.1])  # still the push goal
    assert [str(c) for c in config_changes(push, wider)] == [
        "env.task.goal.distance [0.08, 0.12] -> [0.05, 0.1]"]
    planar = apply_sets(push, ["task.goal=!PlanarGoal {max_yaw: 0.5}"])
    assert planar.env.task.goal == PlanarGoal(max_yaw=0.5)
    with pytest.raises(InputError, match="heading_spread"):
        apply_sets(planar, ["task.goal.heading_spread=0.1"])  # not a PlanarGoal field
    with pytest.raises(InputError, match="bogus"):
        apply_sets(planar, ["task.goal.bogus.deeper=1"])
