"""Hindsight goals for the contact-primitive learner (HER's "future" strategy, Andrychowicz et al.
2017): every finished episode is stored again with goals it did reach.

Why: on push_turn the push policy's primitives turn objects all the time, but rarely to the
episode's goal, so the turn is rewarded too seldom to be learned (the primitive results log, items
11 and 12: re-weighting the reward taught the policy not to push). Relabelled with a pose the
object really reached, the same primitives become examples of turning to that pose.

Each finished episode's transition t gets `goals` more copies, each with the goal set to where
the object was after a later primitive j >= t (uniform over the episode's later states), with the
reward and end PrimitiveEnv would have given for that goal:
    progress_reward * (d(t) - d(t+1)) + success_reward * [success(t+1)]
d: the mean distance between the object's bounding-box keypoints (height dropped) and the goal's
(PrimitiveEnv.keypoint_distance); success: the task's rule (planar xy within success_position
and, where the task checks it, the rotation within success_orientation). A copy ends its episode
(no bootstrap) when it succeeds under its goal or when the original transition ended the episode
without success (left the workspace). The pose where an episode left the workspace is one of
the goals too (keeping it out measured no gain: config/retired.py's hindsight_exit_goals).

Everything comes from the observations. The observation's goal rotation is G = R_goal R^T, and an
episode's goal is fixed, so the rotation from state t to state j is R_j R_t^T = G_j^T G_t; the
positions and keypoints are the observation's own. The features' goal parts are rewritten by
nn/primitive_features.with_goal (no encoder pass).

Left out, on purpose: episodes that ended in a simulation error (their last observation is
zeros); success is checked at the primitive's end only (the env checks every policy period).
With success_at_rest a relabelled success also needs the object still at the primitive's end
(the observation's object_speed), as the env's does.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from corn_drake.config.primitive import REST_ANGULAR_SPEED, REST_LINEAR_SPEED, at_rest
from corn_drake.contract import POSITION_DIM
from corn_drake.nn.primitive_features import with_goal
from corn_drake.systems.reward import within_tolerance
from corn_drake.transforms import from_pose9, rotation_angle


@dataclasses.dataclass(frozen=True)
class HindsightRule:
    goals: int  # relabelled copies per transition
    progress_reward: float
    success_reward: float
    success_position: float  # m, planar
    success_orientation: float  # rad
    check_orientation: bool
    # PrimitiveConfig.success_at_rest and its speeds: a relabelled success also needs the
    # object still at the primitive's end, as the env's own success then does.
    at_rest: bool = False
    rest_linear_speed: float = REST_LINEAR_SPEED
    rest_angular_speed: float = REST_ANGULAR_SPEED

    @classmethod
    def for_run(cls, goals: int, primitive, task) -> HindsightRule | None:
        """The rule of a run (PrimitiveConfig, TaskConfig); None when `goals` is 0 (off)."""
        if not goals:
            return None
        return cls(int(goals), primitive.progress_reward, task.success_reward,
                   task.success_position, task.success_orientation, task.check_orientation,
                   primitive.success_at_rest, primitive.rest_linear_speed,
                   primitive.rest_angular_speed)


@dataclasses.dataclass(frozen=True)
class Achieved:
    """Where one observation puts the object: its position, the goal rotation G = R_goal R^T,
    and the reward's box keypoints with the height of its origin dropped (as
    systems/reward.keypoints_at)."""
    position: np.ndarray  # (3,)
    goal_rotation: np.ndarray  # (3, 3)
    points: np.ndarray  # (8, 3) box corners
    speed: np.ndarray | None = None  # (2,) linear m/s, angular rad/s; None: not observed


def achieved_states(obs: dict[str, np.ndarray]) -> list[Achieved]:
    """One Achieved per row of a batch of primitive-env observations, its points from
    `object_keypoints`, its speed from `object_speed` when given."""
    states = []
    speeds = obs.get("object_speed")
    for i, (position, goal, keypoints) in enumerate(zip(obs["object_position"], obs["goal"],
                                                        obs["object_keypoints"])):
        position = np.asarray(position, np.float64)
        points = np.asarray(keypoints, np.float64).reshape(-1, POSITION_DIM).copy()
        points[:, 2] -= position[2]
        speed = None if speeds is None else np.asarray(speeds[i], np.float64)
        states.append(Achieved(position, from_pose9(goal)[1], points, speed))
    return states


def relative_goal(state: Achieved, goal: Achieved) -> tuple[np.ndarray, np.ndarray]:
    """The observation's goal (position minus the object's, R_goal R^T) at `state` if the
    episode's goal were the pose of `goal` (a state of the same episode)."""
    return goal.position - state.position, goal.goal_rotation.T @ state.goal_rotation


def points_distance(state: Achieved, goal: Achieved) -> float:
    """Mean distance between the reward's points at `state` and at `goal` (PrimitiveEnv's
    keypoint_distance)."""
    return float(np.linalg.norm(state.points - goal.points, axis=1).mean())


def rotation_to(state: Achieved, goal: Achieved) -> float:
    return rotation_angle(goal.goal_rotation.T @ state.goal_rotation)


def succeeded(rule: HindsightRule, state: Achieved, goal: Achieved) -> bool:
    """The task's success rule (systems/reward.within_tolerance) at `state` for `goal`; with
    rule.at_rest also the object still there (an unobserved speed is refused, not guessed)."""
    d = goal.position - state.position
    if not within_tolerance(rule, math.hypot(d[0], d[1]), rotation_to(state, goal)):
        return False
    if not rule.at_rest:
        return True
    if state.speed is None:
        raise ValueError("hindsight at rest: the observation has no object_speed")
    return at_rest({"linear": state.speed[0], "angular": state.speed[1]},
                   rule.rest_linear_speed, rule.rest_angular_speed)


def reward(rule: HindsightRule, before: Achieved, after: Achieved, goal: Achieved) -> float:
    """PrimitiveEnv's reward for the primitive from `before` to `after` had the goal been `goal`."""
    r = rule.progress_reward * (points_distance(before, goal) - points_distance(after, goal))
    if succeeded(rule, after, goal):
        r += rule.success_reward
    return r


@dataclasses.dataclass
class _Step:
    features: dict[str, np.ndarray]  # one state's features (L, ...)
    location: int
    motion: np.ndarray
    terminated: bool
    next_features: dict[str, np.ndarray]
    after: Achieved


class HindsightEpisodes:
    """The unfinished episodes of an env batch, each kept until it ends and is relabelled."""

    def __init__(self, rule: HindsightRule, num_envs: int):
        self.rule = rule
        self._start: list[Achieved | None] = [None] * num_envs
        self._steps: list[list[_Step]] = [[] for _ in range(num_envs)]

    def begin(self, slot: int, state: Achieved) -> None:
        """Env `slot` starts an episode at `state` (anything kept for it is dropped)."""
        self._start[slot], self._steps[slot] = state, []

    def add(self, slot: int, features: dict, location: int, motion: np.ndarray,
            terminated: bool, next_features: dict, after: Achieved) -> None:
        if self._start[slot] is None:
            raise RuntimeError(f"hindsight: env {slot} has no episode begun")
        self._steps[slot].append(_Step(features, int(location), np.asarray(motion, np.float32),
                                       bool(terminated), next_features, after))

    def finish(self, slot: int, succeeded_: bool, relabel: bool,
               rng: np.random.Generator) -> dict[str, object] | None:
        """The relabelled transitions of env `slot`'s episode, which just ended (`succeeded_`
        under its own goal; `relabel` False for a simulation error), as columns
        (features, locations, motions, rewards, terminated, next_features); None if none."""
        start, steps = self._start[slot], self._steps[slot]
        self._start[slot], self._steps[slot] = None, []
        if not relabel or start is None or not steps:
            return None
        states = [start] + [s.after for s in steps]  # state t+1 follows transition t
        # An episode that ended without success (and without a sim error) left the workspace:
        # its last transition ends every copy, whatever the goal.
        exited = steps[-1].terminated and not succeeded_
        rows = []
        for t in range(len(steps)):
            ended_otherwise = exited and t == len(steps) - 1
            for j in rng.integers(t + 1, len(steps) + 1, size=self.rule.goals):
                goal = states[j]
                done = succeeded(self.rule, states[t + 1], goal) or ended_otherwise
                rows.append((t, goal, reward(self.rule, states[t], states[t + 1], goal), done))
        return self._columns(steps, states, rows) if rows else None

    @staticmethod
    def _columns(steps, states, rows) -> dict[str, object]:
        def stacked(key: str) -> dict[str, np.ndarray]:
            return {k: np.stack([getattr(steps[t], key)[k] for t, *_ in rows])
                    for k in getattr(steps[0], key)}

        def goals(offset: int) -> tuple[np.ndarray, np.ndarray]:
            pairs = [relative_goal(states[t + offset], goal) for t, goal, *_ in rows]
            return np.stack([p for p, _ in pairs]), np.stack([R for _, R in pairs])

        return {"features": with_goal(stacked("features"), *goals(0)),
                "locations": np.array([steps[t].location for t, *_ in rows], np.int64),
                "motions": np.stack([steps[t].motion for t, *_ in rows]),
                "rewards": np.array([r for *_, r, _ in rows], np.float32),
                "terminated": np.array([d for *_, d in rows], bool),
                "next_features": with_goal(stacked("next_features"), *goals(1))}
