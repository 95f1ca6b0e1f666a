"""Gymnasium adapters over the rollout diagrams: one env base, one observation set per env.

DiagramEnv holds what every rollout diagram shares (the teacher's systems inside it): one
Simulator built once and reused; reset() draws an Episode (corn_drake/tasks/episode.py) and
writes it into the context (TeacherDiagram.write_episode); step() fixes the action input port,
advances one policy period and reads reward, status and termination; snapshot() and restore()
save and bring back the whole state (the root context and the env's counters), so several
actions can be tried from one state (rl/primitive/outcome/lookahead.py). What the policy sees is
the subclass's: TeacherEnv returns the teacher's privileged observation (TeacherObservationReader);
corn_drake/rl/envs/student_env.py's StudentEnv returns the student's and the teacher's of the same
state. Whole episodes with a policy, recordings and reports are corn_drake/evaluation/episodes.py's job.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np
from pydrake.systems.analysis import InitializeParams, Simulator

from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.contract import ACTION_DIM, OBS_KEYS, check_action
from corn_drake.errors import InputError
from corn_drake.builders.teacher import TeacherDiagram, build_teacher_diagram
from corn_drake.config.plumbing.diagram_files import load_teacher_config
from corn_drake.scene.objects import ObjectSpec
from corn_drake.systems.reward import STATUS_FIELDS
from corn_drake.tasks.episode import Episode, sample_episode
from corn_drake.timing import clock_of


@dataclass(frozen=True)
class EnvSnapshot:
    """DiagramEnv.snapshot()'s value: a copy of the root context and the env's counters."""
    owner: int  # id() of the env it came from: a context only fits its own diagram
    context: object
    counters: dict
    episode: Episode


def zeros_like_space(space: gym.spaces.Space):
    """Zeros with the shapes of a (possibly nested) Dict of Boxes."""
    if isinstance(space, gym.spaces.Dict):
        return {k: zeros_like_space(s) for k, s in space.items()}
    return np.zeros(space.shape, space.dtype)


class TeacherObservationReader:
    """The teacher's privileged observation (OBS_KEYS) from the diagram holding `teacher`."""

    def __init__(self, teacher: TeacherDiagram):
        self._port = teacher.diagram.GetOutputPort("obs.observation")
        self._layout = teacher.observations.layout
        self.space = gym.spaces.Dict({k: gym.spaces.Box(-np.inf, np.inf, self._layout.shapes[k],
                                                        np.float32) for k in OBS_KEYS})

    def read(self, context) -> dict[str, np.ndarray]:
        return self._layout.unpack(self._port.Eval(context))


class DiagramEnv(gym.Env):
    """The env base: subclasses set `observation_space` and define `_observation()`, and may add
    to the info dicts with `_extra_info()`."""

    metadata = {"render_modes": []}

    def __init__(self, teacher: TeacherDiagram, meshcat=None, agent_acts: bool = False):
        """`teacher`: the teacher's handles inside the built diagram (teacher.diagram is the
        whole diagram); `agent_acts`: a PolicySystem inside the diagram chooses the actions."""
        if len(teacher.scene.object_spec.stable_poses) == 0:
            raise ValueError(f"object {teacher.scene.object_spec.name} has no stable poses")
        self._teacher = teacher
        self.teacher_cfg: TeacherDiagramConfig = teacher.config
        self.meshcat = meshcat
        self.diagram = teacher.diagram
        self.scene = teacher.scene
        self.simulator = Simulator(self.diagram)
        self.context = self.simulator.get_mutable_context()
        self._plant_context = self.scene.plant.GetMyMutableContextFromRoot(self.context)
        self._action_port = None if agent_acts else self.diagram.GetInputPort("controller.action")
        self._reward_port = self.diagram.GetOutputPort("task.reward")
        self._status_port = self.diagram.GetOutputPort("task.status")
        self.clock = clock_of(self.teacher_cfg.scene.physics)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (ACTION_DIM,), np.float32)
        self._steps = 0
        self._np_random = np.random.default_rng(self.teacher_cfg.seed)
        self.episode: Episode | None = None  # the current episode's draws (set by reset)
        # The tool's position after every policy period while a list (run_episode sets one
        # when it draws the hand's path in Meshcat); None: nothing kept.
        self.hand_path: list[np.ndarray] | None = None

    # --- what subclasses define ------------------------------------------------------------
    def _observation(self):
        raise NotImplementedError

    def _extra_info(self) -> dict:
        """Entries added to reset's and every (successful) step's info."""
        return {}

    # --- shared ------------------------------------------------------------------------------
    def observation(self):
        """The observation of the env's state now (what reset and step return)."""
        return self._observation()

    @property
    def steps(self) -> int:
        """Policy periods played this episode."""
        return self._steps

    @property
    def plant_context(self):
        """The plant's context inside the simulator's root context."""
        return self._plant_context

    def object_pose(self) -> np.ndarray:
        """The object's pose in the world now, as [p, q_wxyz] (for reports: where it ended)."""
        X = self.scene.plant.EvalBodyPoseInWorld(self._plant_context, self.scene.object_body)
        return np.concatenate([X.translation(), X.rotation().ToQuaternion().wxyz()])

    def place_object(self, pose) -> None:
        """Puts the object at `pose` ([p, q_wxyz], the quaternion normalised), at rest: a
        labelled state's observation rebuilt from its recorded pose (rl/planner/labels.py)."""
        from pydrake.common.eigen_geometry import Quaternion
        from pydrake.math import RigidTransform
        from pydrake.multibody.math import SpatialVelocity

        pose = np.asarray(pose, float)
        if pose.shape != (7,) or not np.all(np.isfinite(pose)) or \
                np.linalg.norm(pose[3:]) < 1e-6:
            raise InputError(f"place_object: a pose is [x, y, z, qw, qx, qy, qz], got {pose}")
        plant, body = self.scene.plant, self.scene.object_body
        plant.SetFreeBodyPose(self._plant_context, body, RigidTransform(
            Quaternion(pose[3:] / np.linalg.norm(pose[3:])), pose[:3]))
        plant.SetFreeBodySpatialVelocity(self._plant_context, body, SpatialVelocity.Zero())

    def tool_position(self) -> np.ndarray:
        """The tool frame's origin in the world now (where the closed fingers push from)."""
        from corn_drake.scene.franka import tool_frame

        frame = tool_frame(self.scene.plant, self.scene.panda)
        return frame.CalcPoseInWorld(self._plant_context).translation().copy()

    def object_speed(self) -> dict[str, float]:
        """The object's speed now: {"linear" (m/s), "angular" (rad/s)}."""
        V = self.scene.plant.EvalBodySpatialVelocityInWorld(self._plant_context,
                                                            self.scene.object_body)
        return {"linear": float(np.linalg.norm(V.translational())),
                "angular": float(np.linalg.norm(V.rotational()))}

    @property
    def policy_in_diagram(self) -> bool:
        """Whether a PolicySystem inside the diagram acts (then step() takes no action)."""
        return self._action_port is None

    def snapshot(self) -> "EnvSnapshot":
        """The env's state now (the diagram's whole context: time, plant, controller, executor;
        and the env's own counters), for restore(): a one-step lookahead tries several actions
        from one state (rl/primitive/outcome/lookahead.py). Every system of the project keeps its state
        in the context, so nothing else needs saving."""
        if self.episode is None:
            raise InputError("snapshot: the env has no episode yet; call reset() first")
        return EnvSnapshot(owner=id(self), context=self.context.Clone(),
                           counters=self._counters(), episode=self.episode)

    def restore(self, snapshot: "EnvSnapshot") -> None:
        """Puts the env back into `snapshot`'s state (one taken from this env by snapshot())."""
        if not isinstance(snapshot, EnvSnapshot) or snapshot.owner != id(self):
            raise InputError("restore: the snapshot was not taken from this env "
                             f"(got {type(snapshot).__name__})")
        self.context.SetTimeStateAndParametersFrom(snapshot.context)
        # The simulator's pending events belong to the time it stopped at: recompute them from
        # the restored time, without the initialization events (they would reset the state).
        self.simulator.Initialize(InitializeParams(suppress_initialization_events=True))
        self.episode = snapshot.episode
        self._set_counters(snapshot.counters)

    def _counters(self) -> dict:
        """The env's own state outside the context (subclasses add theirs)."""
        return {"_steps": self._steps}

    def _set_counters(self, counters: dict) -> None:
        for name, value in counters.items():
            setattr(self, name, value)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is not None:
            self._np_random = np.random.default_rng(seed)
        rng = self._np_random
        self.episode = sample_episode(self.teacher_cfg, self.scene,
                                      self._teacher.observations.tool_pose, rng)
        self._teacher.write_episode(self.context, self.episode, rng)
        if self._action_port is not None:
            self._action_port.FixValue(self.context, np.zeros(ACTION_DIM))
        self.simulator.Initialize()
        self._steps = 0
        return self._observation(), {"status": self._status(), **self._extra_info()}

    def _status(self) -> dict[str, float]:
        return dict(zip(STATUS_FIELDS, self._status_port.Eval(self.context).tolist()))

    def step(self, action=None):
        """One policy step with `action` (normalised, ACTION_DIM); with the policy inside the
        diagram, `action` must be None."""
        if self._action_port is None:
            if action is not None:
                raise ValueError("this env's policy runs inside the diagram: call step() "
                                 "without an action")
        else:
            action = check_action(action)  # raises before touching the simulator
            self._action_port.FixValue(self.context, action)
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
            return zeros_like_space(self.observation_space), 0.0, True, False, info
        if self.hand_path is not None:
            self.hand_path.append(self.tool_position())
        status = self._status()
        info["status"] = status
        info.update(self._extra_info())
        reward = float(self._reward_port.Eval(self.context)[0])
        terminated = bool(status["success"] > 0 or status["out_of_workspace"] > 0)
        truncated = self._steps >= self.teacher_cfg.task.episode_steps and not terminated
        return self._observation(), reward, terminated, truncated, info


class TeacherEnv(DiagramEnv):
    """The teacher rollout diagram; observations: the privileged OBS_KEYS."""

    def __init__(self, config: TeacherDiagramConfig | str | Path | None = None,
                 spec: ObjectSpec | None = None, meshcat=None, agent=None,
                 stochastic_policy: bool = False, attention: bool = False):
        """With `agent`, a PolicySystem inside the diagram chooses the actions (the evaluation
        diagram) and step() takes none; with `stochastic_policy` it samples them (a RandomSource
        the episode's seed reseeds) instead of taking the mean; with `attention`, its attention
        is painted in `meshcat` every step (diagrams.build_teacher_diagram)."""
        if config is None or isinstance(config, (str, Path)):
            config = load_teacher_config(config)
        config.check()
        self.cfg = config
        self.handles: TeacherDiagram = build_teacher_diagram(config, spec, meshcat, agent,
                                                             stochastic_policy, attention)
        super().__init__(self.handles, meshcat, agent_acts=agent is not None)
        self._teacher_obs = TeacherObservationReader(self.handles)
        self.observation_space = self._teacher_obs.space

    def _observation(self) -> dict[str, np.ndarray]:
        return self._teacher_obs.read(self.context)
