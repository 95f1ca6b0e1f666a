"""Episode: one reset's draws, and sample_episode, the one place they are drawn.

Every diagram that runs episodes (the gymnasium env, evaluation, the student's rollouts) draws
an Episode here and writes it into its context with TeacherDiagram.write_episode
(corn_drake/builders/teacher.py).
"""

from __future__ import annotations

import dataclasses
import typing
from typing import Callable

import numpy as np

from corn_drake.scene.randomization import PhysicsSample, sample_physics, scaled_stable_poses
from corn_drake.tasks.sampling import sample_object_and_goal, sample_robot_joints

if typing.TYPE_CHECKING:
    from pydrake.math import RigidTransform

    from corn_drake.config.teacher import TeacherDiagramConfig
    from corn_drake.scene.builder import Scene


@dataclasses.dataclass(frozen=True)
class Episode:
    physics: PhysicsSample  # domain randomization (mass, scale, frictions, restitution, noise)
    initial_joints: np.ndarray  # (NUM_JOINTS,) robot joint positions at the start
    initial_object_pose: np.ndarray  # (7,) [p, q_wxyz] of the object at the start
    goal_pose: np.ndarray  # (7,) [p, q_wxyz] the object must reach


def sample_episode(cfg: TeacherDiagramConfig, scene: Scene,
                   tool_pose: Callable[[np.ndarray], RigidTransform],
                   rng: np.random.Generator) -> Episode:
    """Physics, then robot joints, then the object's start and goal (which may depend on where
    the tool starts: `tool_pose(q)` is its world pose at joints q, e.g.
    TeacherObservations.tool_pose). The draw order is fixed so a seed gives one episode."""
    physics = sample_physics(cfg.randomization, scene, rng)
    q0 = sample_robot_joints(cfg.task, rng)
    hand_xy = tool_pose(q0).translation()[:2]
    spec = scene.object_spec
    start, goal = sample_object_and_goal(
        cfg.task, scaled_stable_poses(spec.stable_poses, physics.scale),
        spec.radius * physics.scale, spec.thin, cfg.scene.table_size, hand_xy, rng)
    return Episode(physics=physics, initial_joints=q0, initial_object_pose=start, goal_pose=goal)
