"""An Episode drawn by corn_drake.tasks and written by TeacherDiagram.write_episode: the same
writer serves the teacher diagram and the student diagram built around the same systems."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from corn_drake.builders.teacher import build_teacher_diagram
from corn_drake.tasks.episode import sample_episode
from corn_drake.timing import clock_of


def _draw(handles, seed):
    rng = np.random.default_rng(seed)
    return sample_episode(handles.config, handles.scene, handles.observations.tool_pose, rng), rng


def _written_state(handles, context):
    plant = handles.scene.plant
    pc = plant.GetMyContextFromRoot(context)
    goal = handles.sources["goal_pose"]
    return (context.get_time(), plant.GetPositions(pc, handles.scene.panda).copy(),
            plant.GetFreeBodyPose(pc, handles.scene.object_body).GetAsMatrix4(),
            goal.get_source_value(goal.GetMyContextFromRoot(context)).value().copy())


def _check_written(handles, context, episode):
    t, q, X, goal = _written_state(handles, context)
    np.testing.assert_array_equal(q, episode.initial_joints)
    np.testing.assert_allclose(X[:3, 3], episode.initial_object_pose[:3])
    np.testing.assert_array_equal(goal, episode.goal_pose)
    assert t == clock_of(handles.config.scene.physics).boundary(0)  # the episode's first step


def test_writing_an_episode_restores_the_defaults_first():
    handles = build_teacher_diagram()
    sim = Simulator(handles.diagram)
    ctx = sim.get_mutable_context()
    handles.diagram.GetInputPort("controller.action").FixValue(ctx, np.zeros(20))
    episode, rng = _draw(handles, 0)
    handles.write_episode(ctx, episode, rng)
    _check_written(handles, ctx, episode)
    first = _written_state(handles, ctx)
    sim.Initialize()
    sim.AdvanceTo(first[0] + 0.5)  # the arm and object move
    assert not np.allclose(_written_state(handles, ctx)[1], first[1])
    episode_again, rng = _draw(handles, 0)
    handles.write_episode(ctx, episode_again, rng)
    again = _written_state(handles, ctx)
    assert again[0] == first[0]
    for a, b in zip(again[1:], first[1:]):
        np.testing.assert_array_equal(a, b)


def test_the_student_diagram_reuses_the_writer():
    from corn_drake.builders.student import build_student_diagram
    from corn_drake.systems.perception.cameras import rendering_available

    ok, reason = rendering_available()
    if not ok:
        pytest.skip(reason)
    student = build_student_diagram()
    handles = student.teacher
    ctx = student.diagram.CreateDefaultContext()
    noise = student.diagram.GetSubsystemByName("goal_noise")

    def written(seed):
        episode, rng = _draw(handles, seed)
        handles.write_episode(ctx, episode, rng)
        _check_written(handles, ctx, episode)
        return noise.get_output_port().Eval(noise.GetMyContextFromRoot(ctx)).copy()

    first = written(1)
    # The student's own noise sources are reseeded from the episode's RNG: a seed replays them.
    assert not np.allclose(written(2), first)
    np.testing.assert_array_equal(written(1), first)
