"""StudentEnv: the gymnasium env over the student rollout diagram (diagrams/student_rollout.yaml).

Same API and episode handling as TeacherEnv (rl/envs/teacher_env.py's DiagramEnv: one env base), but every
observation holds two observation sets of the same state:

    obs = {"student": {key: array for key in STUDENT_OBS_KEYS},   # what a real robot has
           "teacher": {key: array for key in OBS_KEYS}}           # the privileged one

so one rollout serves DAgger both ways: the student acts on obs["student"] and the teacher labels
obs["teacher"]. Both sit in the observation (not in info) because EnvBatch / Ray workers stack
and carry observations, including a new episode's first one after an automatic reset, and
discard info.

info (reset and every step) adds `tracking`: the tracker's estimated pose against the object's
true pose (translation_error_m, rotation_error_deg; the full rotation, so for an object with a
symmetry axis it includes the unobservable roll) with the tracker's status fields and the
segmented point count, for evaluation's tracking statistics.
"""

from __future__ import annotations

import copy
from pathlib import Path

import gymnasium as gym
import numpy as np

from corn_drake.config.student import SEGMENTATION_MODES, StudentDiagramConfig
from corn_drake.contract import STUDENT_OBS_KEYS, student_observation_shapes
from corn_drake.builders.student import StudentDiagram, build_student_diagram
from corn_drake.config.plumbing.diagram_files import load_student_config
from corn_drake.errors import InputError
from corn_drake.rl.envs.teacher_env import DiagramEnv, TeacherObservationReader
from corn_drake.scene.objects import ObjectSpec
from corn_drake.systems.perception.pose_tracker import STATUS_FIELDS as TRACKER_STATUS_FIELDS
from corn_drake.systems.perception.pose_tracker import pose7_to_matrix, pose_error


class StudentObservationReader:
    """The student's observation (STUDENT_OBS_KEYS) from the student diagram's exported ports."""

    def __init__(self, diagram, num_points: int):
        shapes = student_observation_shapes(num_points)
        self._ports = {k: diagram.GetOutputPort(f"student.{k}") for k in STUDENT_OBS_KEYS}
        self._shapes = shapes
        self.space = gym.spaces.Dict({k: gym.spaces.Box(-np.inf, np.inf, shapes[k], np.float32)
                                      for k in STUDENT_OBS_KEYS})

    def read(self, context) -> dict[str, np.ndarray]:
        return {k: np.asarray(p.Eval(context), np.float32).reshape(self._shapes[k])
                for k, p in self._ports.items()}


class StudentEnv(DiagramEnv):
    def __init__(self, config: StudentDiagramConfig | str | Path | None = None,
                 spec: ObjectSpec | None = None, meshcat=None, perception: str | None = None,
                 student=None, stochastic_policy: bool = False):
        """`config`: a StudentDiagramConfig, or a YAML layer read on top of the base student
        diagram (load_student_config). `perception` ("geometric" or "ground_truth") overrides
        the config's segmentation.mode on a copy; the ICP tracker runs in both.

        With `student` (a StudentPolicy in eval mode), a StudentPolicySystem inside the diagram
        chooses the actions from the student observation, its GRU state in the context (the
        student's evaluation diagram), and step() takes none; with `stochastic_policy` it
        samples them (a RandomSource the episode's seed reseeds) instead of taking the mean."""
        if config is None or isinstance(config, (str, Path)):
            config = load_student_config(config)
        if perception is not None:
            if perception not in SEGMENTATION_MODES:
                raise InputError(f"perception must be one of {', '.join(SEGMENTATION_MODES)}, "
                                 f"got {perception!r}")
            config = copy.deepcopy(config)
            config.segmentation.mode = perception
        config.check()
        self.cfg = config
        self.handles: StudentDiagram = build_student_diagram(config, spec, meshcat, student,
                                                             stochastic_policy)
        super().__init__(self.handles.teacher, meshcat, agent_acts=student is not None)
        self._student_obs = StudentObservationReader(self.diagram, config.segmentation.num_points)
        self._teacher_obs = TeacherObservationReader(self.handles.teacher)
        self.observation_space = gym.spaces.Dict({"student": self._student_obs.space,
                                                  "teacher": self._teacher_obs.space})
        self._pose_port = self.diagram.GetOutputPort("perception.pose")
        self._tracker_status_port = self.diagram.GetOutputPort("perception.status")
        self._num_points_port = self.diagram.GetOutputPort("perception.num_points")

    @property
    def perception(self) -> str:
        """The segmentation the chain runs: "geometric" or "ground_truth"."""
        return self.cfg.segmentation.mode

    def _observation(self) -> dict[str, dict[str, np.ndarray]]:
        return {"student": self._student_obs.read(self.context),
                "teacher": self._teacher_obs.read(self.context)}

    def object_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """(estimated, true) 4x4 world poses of the object now: the tracker's output, which the
        student's goal is relative to, and the plant's."""
        X_true = self.scene.plant.EvalBodyPoseInWorld(
            self._plant_context, self.scene.object_body).GetAsMatrix4()
        return pose7_to_matrix(self._pose_port.Eval(self.context)), X_true

    def depth_images(self) -> list[np.ndarray]:
        """The rig's current depth images (m; +inf where nothing returns), camera by camera."""
        return self.handles.perception.rig.depth_images(self.context)

    def tracking_error(self) -> dict[str, float]:
        """The tracker's current estimate against the object's true pose, with its status."""
        X_est, X_true = self.object_poses()
        translation, rotation = pose_error(X_est, X_true)
        status = dict(zip(TRACKER_STATUS_FIELDS, self._tracker_status_port.Eval(self.context).tolist()))
        return {"translation_error_m": translation, "rotation_error_deg": rotation,
                "segmented_points": int(self._num_points_port.Eval(self.context)[0]), **status}

    def _extra_info(self) -> dict:
        return {"tracking": self.tracking_error()}
