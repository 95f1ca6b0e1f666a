"""Draws an episode's robot joints, object start pose and goal pose for a TaskConfig.

One function per goal variant (corn_drake/config/task.py), chosen by the type of `task.goal`.
Each draw that must meet a condition (distance to the hand, goal region, goal distance) gets
TRIES attempts; when none meets it the sampler raises InputError naming the task and the
ranges, because keeping the last, failed draw would silently train on a different task.
Poses are 7-vectors [position, quaternion wxyz], as the diagram's goal_pose source holds them.
"""

from __future__ import annotations

import typing

import numpy as np
from pydrake.math import RotationMatrix

from corn_drake.contract import NUM_JOINTS, POSE7_DIM
from corn_drake.errors import InputError
from corn_drake.scene.franka import JOINT_LOWER, JOINT_UPPER
from corn_drake.config.task import Full6dGoal, PlanarGoal, PushFromHandGoal
from corn_drake.transforms import quat_wxyz_to_matrix, yaw_matrix

if typing.TYPE_CHECKING:
    from corn_drake.config.task import TaskConfig

TRIES = 1000
TABLE_MARGIN = 0.95  # objects start within 95 % of the table, minus their radius


def pose7(p: np.ndarray, R: np.ndarray) -> np.ndarray:
    q = RotationMatrix(R).ToQuaternion()
    return np.array([*p, q.w(), q.x(), q.y(), q.z()])


def sample_robot_joints(task: TaskConfig, rng: np.random.Generator) -> np.ndarray:
    """Uniform in [robot_init_low, robot_init_high] plus N(0, robot_init_noise), clipped to the
    joint limits."""
    q = rng.uniform(task.robot_init_low, task.robot_init_high)
    q = q + rng.normal(0.0, task.robot_init_noise, NUM_JOINTS)
    return np.clip(q, JOINT_LOWER, JOINT_UPPER)


class _Draw:
    """The arguments every variant's sampler shares."""

    def __init__(self, task: TaskConfig, stable_poses: np.ndarray, radius: float, thin: bool,
                 table_size, hand_xy: np.ndarray, rng: np.random.Generator):
        self.task, self.poses, self.thin, self.rng = task, stable_poses, thin, rng
        self.radius = radius
        self.hand_xy = np.asarray(hand_xy, float)
        # Where an object of this radius may start: the table shrunk by the margin and radius.
        self.half = np.maximum(np.asarray(table_size[:2], float) / 2 * TABLE_MARGIN - radius, 0.0)
        self.goal_lo = np.array([task.goal_x[0], task.goal_y[0]])
        self.goal_hi = np.array([task.goal_x[1], task.goal_y[1]])

    def in_goal_region(self, xy: np.ndarray) -> bool:
        return bool(np.all(xy >= self.goal_lo) and np.all(xy <= self.goal_hi))

    def stable_pose(self) -> np.ndarray:
        return self.poses[self.rng.integers(len(self.poses))]

    def start_xy(self, min_distance_to_hand: float) -> np.ndarray:
        for _ in range(TRIES):
            xy = self.rng.uniform(-self.half, self.half)
            if np.linalg.norm(xy - self.hand_xy) >= min_distance_to_hand:
                return xy
        raise self.unmet("object start", f"task.goal.object_min_distance_to_hand "
                                         f"{min_distance_to_hand} m")

    def start(self, min_distance_to_hand: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(start pose7, its stable pose, its rotation): a random stable pose at a random yaw,
        at least min_distance_to_hand (xy) from the tool. The draw order (xy, pose, yaw) is
        what fixed seeds reproduce."""
        xy = self.start_xy(min_distance_to_hand)
        init = self.stable_pose()
        R0 = yaw_matrix(self.rng.uniform(-np.pi, np.pi)) @ quat_wxyz_to_matrix(init[3:])
        return _placed(xy, init, R0), init, R0

    def unmet(self, what: str, ranges: str) -> InputError:
        t = self.task
        return InputError(
            f"task {t.name!r}: no {what} in {TRIES} draws with {ranges}, the tool at xy "
            f"{self.hand_xy.round(3).tolist()}, the object (radius {self.radius:.3f} m) starting "
            f"within +-{self.half.round(3).tolist()} m of the table centre and task.goal_x "
            f"{t.goal_x} / task.goal_y {t.goal_y}; widen the ranges")


def _placed(xy: np.ndarray, stable_pose: np.ndarray, R: np.ndarray) -> np.ndarray:
    """A stable pose's height and xy offset, moved to xy and turned to R."""
    return pose7([xy[0] + stable_pose[0], xy[1] + stable_pose[1], stable_pose[2]], R)


def _full6d(d: _Draw, g: Full6dGoal) -> tuple[np.ndarray, np.ndarray]:
    rng = d.rng
    start, init, _ = d.start(g.object_min_distance_to_hand)
    goal_pose = init if d.thin else d.stable_pose()
    for _ in range(TRIES):
        gxy = np.array([rng.uniform(*d.task.goal_x), rng.uniform(*d.task.goal_y)])
        if np.linalg.norm(gxy - start[:2]) >= g.min_goal_distance:
            break
    else:
        raise d.unmet("goal", f"task.goal.min_goal_distance {g.min_goal_distance} m from the "
                              f"start at xy {start[:2].round(3).tolist()}")
    Rg = yaw_matrix(rng.uniform(-np.pi, np.pi)) @ quat_wxyz_to_matrix(goal_pose[3:])
    return start, _placed(gxy, goal_pose, Rg)


def _planar(d: _Draw, g: PlanarGoal) -> tuple[np.ndarray, np.ndarray]:
    rng = d.rng
    start, _, R0 = d.start(g.object_min_distance_to_hand)
    for _ in range(TRIES):
        heading = rng.uniform(-np.pi, np.pi)
        gxy = start[:2] + rng.uniform(*g.distance) * np.array([np.cos(heading), np.sin(heading)])
        if d.in_goal_region(gxy):
            break
    else:
        raise d.unmet("goal", f"task.goal.distance {g.distance} m from the start at xy "
                              f"{start[:2].round(3).tolist()}")
    Rg = yaw_matrix(rng.uniform(-g.max_yaw, g.max_yaw)) @ R0
    return start, pose7([gxy[0], gxy[1], start[2]], Rg)


def _push_from_hand(d: _Draw, g: PushFromHandGoal) -> tuple[np.ndarray, np.ndarray]:
    # Object and goal are drawn together: whether a goal fits depends on where the object is.
    rng = d.rng
    init = d.stable_pose()
    R0 = yaw_matrix(rng.uniform(-np.pi, np.pi)) @ quat_wxyz_to_matrix(init[3:])
    lo, hi = g.object_distance_to_hand
    for _ in range(TRIES):
        xy = rng.uniform(-d.half, d.half)
        away = xy - d.hand_xy
        if not lo <= np.linalg.norm(away) <= hi:
            continue
        heading = np.arctan2(away[1], away[0]) + rng.uniform(-g.heading_spread, g.heading_spread)
        gxy = xy + rng.uniform(*g.distance) * np.array([np.cos(heading), np.sin(heading)])
        if d.in_goal_region(gxy):
            start = _placed(xy, init, R0)
            Rg = yaw_matrix(rng.uniform(-g.max_yaw, g.max_yaw)) @ R0
            return start, pose7([gxy[0] + init[0], gxy[1] + init[1], start[2]], Rg)
    raise d.unmet("object/goal pair", f"task.goal.object_distance_to_hand "
                                      f"{g.object_distance_to_hand} m, task.goal.distance "
                                      f"{g.distance} m and task.goal.heading_spread "
                                      f"{g.heading_spread} rad")


_SAMPLERS = {Full6dGoal: _full6d, PlanarGoal: _planar, PushFromHandGoal: _push_from_hand}


def sample_object_and_goal(task: TaskConfig, stable_poses: np.ndarray, radius: float,
                           thin: bool, table_size, hand_xy: np.ndarray,
                           rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(start pose, goal pose) of the object, each a 7-vector [p, q_wxyz], for `task.goal`.

    stable_poses: (n, 7) the object's resting poses at the table centre (already scaled);
    radius: its bounding radius (scaled); thin: whether it only gets yaw goals (Full6dGoal);
    table_size: the table's [x, y, z] extent; hand_xy: the tool's xy at the episode's start.
    """
    task.check()
    if len(stable_poses) == 0 or np.shape(stable_poses)[1:] != (POSE7_DIM,):
        raise InputError(f"task {task.name!r}: the object needs stable poses as (n, "
                         f"{POSE7_DIM}) rows, got shape {np.shape(stable_poses)}")
    draw = _Draw(task, np.asarray(stable_poses), radius, thin, table_size, hand_xy, rng)
    return _SAMPLERS[type(task.goal)](draw, task.goal)
