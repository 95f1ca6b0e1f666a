"""TeacherEnv: a gymnasium env over the teacher rollout diagram.

One Simulator is built once and reused: reset() writes a fresh episode (domain randomization,
robot joints, object pose, goal) into the context, step() fixes the action input port and
advances one policy period.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.analysis import Simulator

from corn_drake.config import TeacherDiagramConfig
from corn_drake.diagrams import (TeacherDiagram, build_teacher_diagram, load_teacher_config,
                                 reseed_random_sources)
from corn_drake.scene.franka import JOINT_LOWER, JOINT_UPPER, NUM_JOINTS
from corn_drake.scene.objects import ObjectSpec
from corn_drake.scene.randomization import apply_physics, sample_physics, scaled_stable_poses
from corn_drake.systems.ik import ACTION_DIM, check_action
from corn_drake.systems.observations import OBS_KEYS
from corn_drake.systems.reward import STATUS_FIELDS, reset_previous
from corn_drake.timing import clock_of
from corn_drake.transforms import quat_wxyz_to_matrix, yaw_matrix

TABLE_MARGIN = 0.95  # objects start within 95 % of the table, minus their radius


def _pose7(p, R) -> np.ndarray:
    q = RotationMatrix(R).ToQuaternion()
    return np.array([*p, q.w(), q.x(), q.y(), q.z()])


class TeacherEnv(gym.Env):
    metadata = {"render_modes": []}

    def __init__(self, config: TeacherDiagramConfig | str | Path | None = None,
                 spec: ObjectSpec | None = None, meshcat=None, agent=None):
        """With `agent`, the policy runs inside the diagram: use run_closed_loop(), not step()."""
        if config is None or isinstance(config, (str, Path)):
            config = load_teacher_config(config)
        self.cfg = config
        self.handles: TeacherDiagram = build_teacher_diagram(config, spec, meshcat, agent)
        if len(self.handles.scene.object_spec.stable_poses) == 0:
            raise ValueError(f"object {self.handles.scene.object_spec.name} has no stable poses")
        self.meshcat = meshcat
        self.diagram = self.handles.diagram
        self.scene = self.handles.scene
        self.simulator = Simulator(self.diagram)
        self.context = self.simulator.get_mutable_context()
        self._default_context = self.diagram.CreateDefaultContext()
        self._plant_context = self.scene.plant.GetMyMutableContextFromRoot(self.context)
        self._action_port = (self.diagram.GetInputPort("controller.action")
                             if agent is None else None)
        self._obs_port = self.diagram.GetOutputPort("obs.observation")
        self._layout = self.handles.observations.layout
        self._reward_port = self.diagram.GetOutputPort("task.reward")
        self._status_port = self.diagram.GetOutputPort("task.status")
        self.clock = clock_of(config.scene.physics)
        self._scale = 1.0
        self.observation_space = gym.spaces.Dict(
            {k: gym.spaces.Box(-np.inf, np.inf, self._layout.shapes[k], np.float32) for k in OBS_KEYS})
        self.action_space = gym.spaces.Box(-1.0, 1.0, (ACTION_DIM,), np.float32)
        self._steps = 0
        self._np_random = np.random.default_rng(config.seed)
        self.episode_info: dict = {}

    @property
    def plant_context(self):
        """The plant's context inside the simulator's root context."""
        return self._plant_context

    # --- episode sampling --------------------------------------------------------------------
    def _sample_robot(self, rng) -> np.ndarray:
        t = self.cfg.task
        q = rng.uniform(t.robot_init_low, t.robot_init_high)
        q = q + rng.normal(0.0, t.robot_init_noise, NUM_JOINTS)
        return np.clip(q, JOINT_LOWER, JOINT_UPPER)

    def _sample_object_and_goal(self, rng, poses: np.ndarray, radius: float, hand_xy: np.ndarray):
        t, spec = self.cfg.task, self.scene.object_spec
        half = np.asarray(self.cfg.scene.table_size[:2]) / 2 * TABLE_MARGIN - radius
        half = np.maximum(half, 0.0)
        if t.goal_mode == "planar" and t.planar_heading_spread is not None:
            return self._push_from_hand(rng, poses, half, hand_xy)
        for _ in range(1000):
            xy = rng.uniform(-half, half)
            if (t.object_min_distance_to_hand <= np.linalg.norm(xy - hand_xy)
                    <= t.object_max_distance_to_hand):
                break
        init = poses[rng.integers(len(poses))]
        R0 = yaw_matrix(rng.uniform(-np.pi, np.pi)) @ quat_wxyz_to_matrix(init[3:])
        p0 = np.array([xy[0] + init[0], xy[1] + init[1], init[2]])
        if t.goal_mode == "planar":
            return p0, R0, *self._planar_goal(rng, p0, R0)
        if t.goal_mode != "full":
            raise ValueError(f"task.goal_mode must be 'full' or 'planar', got {t.goal_mode!r}")
        # Thin objects (cards, plates) only get yaw goals: they cannot be stood up by pushing.
        goal = init if spec.thin else poses[rng.integers(len(poses))]
        for _ in range(1000):
            gxy = np.array([rng.uniform(*t.goal_x), rng.uniform(*t.goal_y)])
            if np.linalg.norm(gxy - p0[:2]) >= t.min_goal_distance:
                break
        Rg = yaw_matrix(rng.uniform(-np.pi, np.pi)) @ quat_wxyz_to_matrix(goal[3:])
        pg = np.array([gxy[0] + goal[0], gxy[1] + goal[1], goal[2]])
        return p0, R0, pg, Rg

    def _goal_region(self) -> tuple[np.ndarray, np.ndarray]:
        t = self.cfg.task
        return np.array([t.goal_x[0], t.goal_y[0]]), np.array([t.goal_x[1], t.goal_y[1]])

    def _planar_goal(self, rng, p0: np.ndarray, R0: np.ndarray):
        """Same resting face, moved planar_distance and turned up to planar_max_yaw."""
        t = self.cfg.task
        lo, hi = self._goal_region()
        for _ in range(1000):
            heading = rng.uniform(-np.pi, np.pi)
            gxy = p0[:2] + rng.uniform(*t.planar_distance) * np.array([np.cos(heading), np.sin(heading)])
            if np.all(gxy >= lo) and np.all(gxy <= hi):
                break
        Rg = yaw_matrix(rng.uniform(-t.planar_max_yaw, t.planar_max_yaw)) @ R0
        return np.array([gxy[0], gxy[1], p0[2]]), Rg

    def _push_from_hand(self, rng, poses: np.ndarray, half: np.ndarray, hand_xy: np.ndarray):
        """Object and goal drawn together: the object within the hand-distance range, the goal
        planar_distance beyond it, within +- planar_heading_spread of the hand-to-object
        direction and inside the goal region; same resting face, yaw up to planar_max_yaw."""
        t = self.cfg.task
        lo, hi = self._goal_region()
        init = poses[rng.integers(len(poses))]
        R0 = yaw_matrix(rng.uniform(-np.pi, np.pi)) @ quat_wxyz_to_matrix(init[3:])
        for _ in range(1000):
            xy = rng.uniform(-half, half)
            away = xy - hand_xy
            distance = np.linalg.norm(away)
            if not t.object_min_distance_to_hand <= distance <= t.object_max_distance_to_hand:
                continue
            heading = np.arctan2(away[1], away[0]) + rng.uniform(-t.planar_heading_spread,
                                                                 t.planar_heading_spread)
            gxy = xy + rng.uniform(*t.planar_distance) * np.array([np.cos(heading), np.sin(heading)])
            if np.all(gxy >= lo) and np.all(gxy <= hi):
                p0 = np.array([xy[0] + init[0], xy[1] + init[1], init[2]])
                Rg = yaw_matrix(rng.uniform(-t.planar_max_yaw, t.planar_max_yaw)) @ R0
                return p0, R0, np.array([gxy[0] + init[0], gxy[1] + init[1], p0[2]]), Rg
        raise ValueError(
            f"task: no object/goal pair in 1000 draws with the object "
            f"{t.object_min_distance_to_hand}-{t.object_max_distance_to_hand} m from the hand at "
            f"{hand_xy.round(3).tolist()}, planar_distance {t.planar_distance} and goal_x "
            f"{t.goal_x} / goal_y {t.goal_y}; widen the ranges")

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is not None:
            self._np_random = np.random.default_rng(seed)
        rng = self._np_random
        h, scene, spec = self.handles, self.scene, self.scene.object_spec
        ctx = self.context
        ctx.SetTimeStateAndParametersFrom(self._default_context)
        ctx.SetTime(self.clock.boundary(0))
        self._scale = 1.0  # the default context holds the unscaled shapes again
        phys = sample_physics(self.cfg.randomization, scene, rng)
        apply_physics(scene, phys, ctx, self._scale)
        self._scale = phys.scale
        s = phys.scale

        q0 = self._sample_robot(rng)
        scene.plant.SetPositions(self._plant_context, scene.panda, q0)
        hand_xy = h.observations.tool_pose(q0).translation()[:2]
        poses = scaled_stable_poses(spec.stable_poses, s)
        p0, R0, pg, Rg = self._sample_object_and_goal(rng, poses, spec.radius * s, hand_xy)
        scene.plant.SetFreeBodyPose(self._plant_context, scene.object_body,
                                    RigidTransform(RotationMatrix(R0), p0))

        def set_source(name, value):
            src = h.sources[name]
            src.get_mutable_source_value(src.GetMyMutableContextFromRoot(ctx)).set_value(
                np.asarray(value, float))

        set_source("goal_pose", _pose7(pg, Rg))
        set_source("physics_params", phys.as_observation())
        set_source("object_cloud", s * spec.cloud[h.cloud_indices, :3].reshape(-1))
        set_source("object_keypoints", s * spec.bbox_corners.reshape(-1))
        set_source("object_radius", [s * spec.radius])
        set_source("torque_noise_std", [phys.torque_noise_std])

        # After the episode's draws, so a seed gives the same episode with or without noise.
        reseed_random_sources(self.diagram, ctx, rng)
        h.ik.hold_position(h.ik.GetMyMutableContextFromRoot(ctx), q0)
        reset_previous(h.reward_hold, h.reward, ctx)
        if self._action_port is not None:
            self._action_port.FixValue(ctx, np.zeros(ACTION_DIM))
        self.simulator.Initialize()
        self._steps = 0
        self.episode_info = {"physics": phys, "goal_pose": _pose7(pg, Rg),
                             "initial_object_pose": _pose7(p0, R0), "initial_joints": q0}
        return self._observation(), {"status": self._status()}

    # --- stepping ----------------------------------------------------------------------------
    def _observation(self) -> dict[str, np.ndarray]:
        return self._layout.unpack(self._obs_port.Eval(self.context))

    def _status(self) -> dict[str, float]:
        return dict(zip(STATUS_FIELDS, self._status_port.Eval(self.context).tolist()))

    def step(self, action):
        if self._action_port is None:
            raise RuntimeError("this env's policy runs inside the diagram; use run_closed_loop()")
        action = check_action(action)  # raises before touching the simulator
        self._action_port.FixValue(self.context, action)
        return self._advance()

    def run_closed_loop(self) -> tuple[int, float, dict, dict]:
        """Runs the in-diagram policy until the episode ends: (steps, return, status, info)."""
        total, steps = 0.0, 0
        while True:
            _, reward, terminated, truncated, info = self._advance()
            total += reward
            steps += 1
            if terminated or truncated:
                return steps, total, info.get("status", {}), info

    def _advance(self):
        info: dict = {}
        try:
            self.simulator.AdvanceTo(self.clock.boundary(self._steps + 1))
        except RuntimeError as e:  # a solver failure: end the episode, keep the run alive
            info["sim_error"] = str(e)
        state_ok = "sim_error" not in info and np.isfinite(
            self.scene.plant.GetPositionsAndVelocities(self._plant_context)).all()
        self._steps += 1
        if not state_ok:
            # The episode ends as terminated, not truncated: a time-out makes PPO bootstrap
            # from V(final observation), and the state behind this one is meaningless. The
            # zero observation only keeps the shapes; reset() before stepping again.
            info.setdefault("sim_error", "non-finite state after step")
            obs = {k: np.zeros(sp.shape, np.float32) for k, sp in self.observation_space.items()}
            return obs, 0.0, True, False, info
        status = self._status()
        info["status"] = status
        reward = float(self._reward_port.Eval(self.context)[0])
        terminated = bool(status["success"] > 0 or status["out_of_workspace"] > 0)
        truncated = self._steps >= self.cfg.task.episode_steps and not terminated
        return self._observation(), reward, terminated, truncated, info

    # --- visualisation -----------------------------------------------------------------------
    def start_recording(self) -> None:
        if self.meshcat is None:
            raise RuntimeError("TeacherEnv was built without meshcat; pass meshcat=Meshcat()")
        self.meshcat.StartRecording(set_visualizations_while_recording=False)

    def save_recording(self, path) -> Path:
        from corn_drake.viz.meshcat import save_recording

        self.meshcat.StopRecording()
        return save_recording(self.meshcat, path)
