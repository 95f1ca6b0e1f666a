"""PrimitiveEnv: the contact-primitive policy's gymnasium env — one step is one whole primitive.

The diagram is builders/primitive.py's: the teacher's plant, controller, observations, reward
and status, with a PrimitiveExecutor in the PolicySystem's place. step(action) takes
{"point": index into the observation's cloud, "motion": (3,) in [-1, 1]}, looks the point and
its outward normal up in the current observation, hands the executor the primitive and advances
the policy clock period after period (each the teacher env's step: 8 physics steps) until the
executor is idle again, the task succeeds, the object leaves the workspace, the simulation
fails, or the task's episode_steps run out. The reward is PrimitiveConfig.progress_reward times
how much the primitive closed the mean distance between the object's bounding-box keypoints and
the goal's (the paper's keypoints: position and the full 3-D orientation), plus the task's
success_reward on success; info["task_reward"] keeps the teacher's per-period rewards summed.

Episode end: success or out of workspace (terminated); max_primitives primitives (HACMan's 10)
or the task's episode_steps of policy periods (truncated), whichever comes first. With PrimitiveConfig.success_at_rest a success mid-primitive does not end the step:
the primitive runs to its end, and the success stands only if the object is then still at the
goal (the in-diagram path judges the same way, at the period the executor is idle).

Observation: the teacher's privileged keys (cloud, hand_state, ..., object_keypoints) plus
`normals` (N, 3: the cloud's outward normals, world frame), `object_position` (3),
`executor` (the executor's status, STATUS_DIM) and `object_speed` (2: linear m/s, angular rad/s;
hindsight goals judge a relabelled success at rest by it). info adds `ticks` (policy periods the primitive
took), `reached` (whether the pre-contact pose was reached) and `primitive` (the vector sent).
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

from corn_drake.config.plumbing.bounds import check_bounds
from corn_drake.config.plumbing.diagram_files import load_teacher_config
from corn_drake.config.primitive import PrimitiveConfig, at_rest
from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.contract import POSITION_DIM
from corn_drake.errors import InputError
from corn_drake.rl.envs.teacher_env import DiagramEnv, TeacherObservationReader, zeros_like_space
from corn_drake.scene.objects import ObjectSpec
from corn_drake.systems.control.low_push import push_contact
from corn_drake.systems.control.primitive_executor import (IDLE, PRIMITIVE_DIM, STATUS_DIM,
                                                           STATUS_LAYOUT, make_primitive)

PRIMITIVE_OBS_KEYS = ("normals", "object_position", "executor", "object_speed")


def _brief(value) -> str:
    """`value`'s repr on one line, cut to 80 characters (an error message names it)."""
    return " ".join(repr(value).split())[:80]


def check_primitive_action(action, num_points: int) -> tuple[int, np.ndarray]:
    """(point index, motion) of an env action, or a one-line InputError naming what is wrong."""
    if not isinstance(action, dict) or set(action) != {"point", "motion"}:
        raise InputError(f"primitive action must be a dict with keys 'point' and 'motion', got "
                         f"{_brief(action)}")
    point = np.asarray(action["point"])
    if point.size != 1 or not np.issubdtype(point.dtype, np.integer) \
            or not 0 <= int(point.reshape(-1)[0]) < num_points:
        raise InputError(f"primitive action 'point' must be an integer index into the "
                         f"{num_points}-point cloud, got {_brief(action['point'])}")
    try:
        motion = np.asarray(action["motion"], float).reshape(-1)
    except (TypeError, ValueError):  # not numbers at all (a string, a ragged list)
        motion = None
    if motion is None or motion.shape != (POSITION_DIM,) or not np.isfinite(motion).all():
        raise InputError(f"primitive action 'motion' must be 3 finite numbers, got "
                         f"{_brief(action['motion'])}")
    return int(point.reshape(-1)[0]), np.clip(motion, -1.0, 1.0)


class PrimitiveEnv(DiagramEnv):
    def __init__(self, config: TeacherDiagramConfig | str | Path | None = None,
                 primitive: PrimitiveConfig | None = None, spec: ObjectSpec | None = None,
                 meshcat=None, agent=None):
        """With `agent` (a PrimitiveAgent), a PrimitivePolicySystem inside the diagram chooses
        the primitives (the evaluation diagram): step() then takes no action and advances one
        policy period, as the teacher's evaluation env does."""
        from corn_drake.builders.primitive import build_primitive_diagram

        if config is None or isinstance(config, (str, Path)):
            config = load_teacher_config(config)
        config.check()
        self.cfg, self.primitive_cfg = config, primitive or PrimitiveConfig()
        # A PrimitiveConfig made in code is checked as a run's config is (its ranges too).
        check_bounds(self.primitive_cfg, "primitive.")
        self.handles = build_primitive_diagram(config, self.primitive_cfg, spec, meshcat, agent)
        super().__init__(self.handles.teacher, meshcat, agent_acts=True)
        self._agent_inside = agent is not None
        d = self.diagram
        self._primitive_port = None if agent is not None else d.GetInputPort("executor.primitive")
        self._executor_port = d.GetOutputPort("executor.status")
        self._normals_port = d.GetOutputPort("object.normals")
        self._position_port = d.GetOutputPort("object.position")
        self._teacher_obs = TeacherObservationReader(self.handles.teacher)
        n = config.scene.object.cloud_points
        spaces = dict(self._teacher_obs.space.spaces)
        spaces["normals"] = gym.spaces.Box(-1.0, 1.0, (n, POSITION_DIM), np.float32)
        spaces["object_position"] = gym.spaces.Box(-np.inf, np.inf, (POSITION_DIM,), np.float32)
        spaces["executor"] = gym.spaces.Box(-np.inf, np.inf, (STATUS_DIM,), np.float32)
        spaces["object_speed"] = gym.spaces.Box(0.0, np.inf, (2,), np.float32)
        self.observation_space = gym.spaces.Dict(spaces)
        self.action_space = gym.spaces.Dict({
            "point": gym.spaces.Discrete(n),
            "motion": gym.spaces.Box(-1.0, 1.0, (POSITION_DIM,), np.float32)})
        self.primitives = 0  # primitives sent this episode

    def _observation(self) -> dict[str, np.ndarray]:
        obs = self._teacher_obs.read(self.context)
        obs["normals"] = np.asarray(self._normals_port.Eval(self.context), np.float32).reshape(
            -1, POSITION_DIM)
        obs["object_position"] = np.asarray(self._position_port.Eval(self.context), np.float32)
        obs["executor"] = np.asarray(self._executor_port.Eval(self.context), np.float32)
        speed = self.object_speed()
        obs["object_speed"] = np.array([speed["linear"], speed["angular"]], np.float32)
        return obs

    def executor_status(self) -> np.ndarray:
        return np.asarray(self._executor_port.Eval(self.context))

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if self._primitive_port is not None:
            # Sequence 0: nothing to start until step() sends primitive 1.
            self._primitive_port.FixValue(self.context, np.zeros(PRIMITIVE_DIM))
        self.primitives = 0
        return super().reset(seed=seed, options=options)

    def step(self, action=None, aim: tuple | None = None):
        """One primitive (see the module docstring); with the policy inside the diagram, one
        policy period (action None), as TeacherEnv. `aim` ((point, normal) in the world): aim
        the primitive exactly there instead of at `aim(obs, point)` (a planner's topple)."""
        if self._agent_inside:
            obs, reward, terminated, truncated, info = super().step(action)
            status = self.executor_status()
            if self.primitive_cfg.success_at_rest and "sim_error" not in info:
                terminated, truncated = self._judge_at_rest(
                    info, status[STATUS_LAYOUT["phase"]] == IDLE)
            if status[STATUS_LAYOUT["phase"]] == IDLE and not terminated and \
                    round(status[STATUS_LAYOUT["count"]]) >= self.primitive_cfg.max_primitives:
                truncated = True  # the primitive budget is spent, as in training
            return obs, reward, terminated, truncated, info
        point, motion = check_primitive_action(action, self.cfg.scene.object.cloud_points)
        obs = self._observation()
        status = obs["executor"]
        sequence = int(round(status[STATUS_LAYOUT["count"]])) + 1
        target, normal = self.aim(obs, point) if aim is None else \
            (np.asarray(aim[0], float), np.asarray(aim[1], float))
        primitive = make_primitive(target, normal, motion, point, sequence)
        self._primitive_port.FixValue(self.context, primitive)
        distance_before = self.keypoint_distance()
        total, ticks = 0.0, 0
        while True:
            obs, reward, terminated, truncated, info = super().step(None)
            total += reward
            ticks += 1
            if terminated or truncated:
                if not (terminated and self._success_waits(info)):
                    break
                terminated = False  # at rest only: judged when the primitive has ended
            status = self.executor_status()
            if status[STATUS_LAYOUT["phase"]] == IDLE and \
                    round(status[STATUS_LAYOUT["count"]]) >= sequence:
                break
        self.primitives += 1
        if "sim_error" in info:
            return zeros_like_space(self.observation_space), total, True, False, info
        status = self.executor_status()
        if self.primitive_cfg.success_at_rest:
            terminated, truncated = self._judge_at_rest(
                info, status[STATUS_LAYOUT["phase"]] == IDLE)
        truncated = truncated or (not terminated and
                                  self.primitives >= self.primitive_cfg.max_primitives)
        info.update({"ticks": ticks, "reached": bool(status[STATUS_LAYOUT["reached"]] > 0),
                     "primitive": primitive, "task_reward": total})
        reward = self.primitive_cfg.progress_reward * (distance_before - self.keypoint_distance())
        if info["status"]["success"] > 0:
            reward += self.cfg.task.success_reward
        return obs, reward, terminated, truncated, info

    def aim(self, obs: dict, point: int) -> tuple[np.ndarray, np.ndarray]:
        """(point, normal) the primitive aims at for cloud point `point`: low_push's choice
        (a planner's topple, rl/planner/kinds.py, passes step() an exact aim instead)."""
        return push_contact(obs["cloud"], obs["normals"], point, self.primitive_cfg)

    def _success_waits(self, info: dict) -> bool:
        """Whether a success mid-primitive waits for the primitive's end (success_at_rest), the
        episode's periods not yet spent."""
        status = info["status"]
        return self.primitive_cfg.success_at_rest and status["success"] > 0 and \
            status["out_of_workspace"] <= 0 and self.steps < self.cfg.task.episode_steps

    def object_still(self) -> bool:
        """The object moves slower than PrimitiveConfig's rest speeds (linear and angular)."""
        return at_rest(self.object_speed(), self.primitive_cfg.rest_linear_speed,
                       self.primitive_cfg.rest_angular_speed)

    def _judge_at_rest(self, info: dict, idle: bool) -> tuple[bool, bool]:
        """(terminated, truncated) under success_at_rest: the task's success stands only with
        the executor idle and the object still; otherwise info's status says no success and the
        episode goes on (unless it left the workspace or its periods are spent)."""
        status = info["status"]
        if status["success"] > 0 and not (idle and self.object_still()):
            status["success"] = 0.0
        terminated = status["success"] > 0 or status["out_of_workspace"] > 0
        truncated = not terminated and self.steps >= self.cfg.task.episode_steps
        return terminated, truncated

    def _counters(self) -> dict:
        return {**super()._counters(), "primitives": self.primitives}

    def body_points(self, source: str = "object_keypoints") -> np.ndarray:
        """(P, 3) points of the object in its body frame, from the teacher's per-episode
        `source`: its bounding-box keypoints (the reward's) by default."""
        system = self.handles.teacher.sources[source]
        return system.get_source_value(system.GetMyContextFromRoot(self.context)
                                       ).value().reshape(-1, POSITION_DIM)

    def keypoint_distance(self) -> float:
        """Mean distance (m) between the object's bounding-box keypoints now and at the goal:
        the distance the progress reward closes (the reward's keypoints,
        systems/reward.keypoints_at: the height of the object's origin dropped, its tilt
        kept)."""
        from corn_drake.systems.reward import keypoints_at
        from corn_drake.transforms import quat_wxyz_to_matrix

        pose, goal = self.object_pose(), np.asarray(self.episode.goal_pose, float)
        R = quat_wxyz_to_matrix(pose[3:])
        points = self.body_points()
        d = keypoints_at(points, pose[:3], R) - keypoints_at(points, goal[:3],
                                                            quat_wxyz_to_matrix(goal[3:]))
        return float(np.linalg.norm(d, axis=1).mean())
