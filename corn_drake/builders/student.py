"""The student rollout diagram: the teacher's scene and systems plus the perception chain.

    plant/scene graph --> 3 RgbdSensors --> DepthImageToPointCloud (x3, world frame)
        --> ObjectSegmentation (robot state for the link test) --> PoseTracker (ICP)
        --> StudentObservations (+ RandomSource cloud and goal noise)

Exported ports (besides the teacher's, see corn_drake.builders.teacher): input `controller.action`
(absent when a StudentPolicySystem acts inside the diagram);
outputs `student.<key>` for STUDENT_OBS_KEYS, `perception.pose` (pose7, estimated),
`perception.status` (PoseTracker STATUS_FIELDS), `perception.num_points`,
`perception.object_cloud` (PointCloud of the segmented points).

Config: `load_student_config(path, base)` reads a YAML layer (default: the base diagram
diagrams/student_rollout.yaml) on top of `base` (default: StudentDiagramConfig()'s defaults).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.common import RandomDistribution
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import MatrixGain, RandomSource

from corn_drake.config.plumbing.diagram_files import load_student_config
from corn_drake.config.student import StudentDiagramConfig
from corn_drake.contract import (FREE_BODY_POSITION, FREE_BODY_QUATERNION, FREE_BODY_STATE_DIM,
                                 POSE7_DIM, POSE7_POSITION, POSE7_QUATERNION, STUDENT_OBS_KEYS)
from corn_drake.builders.teacher import TeacherDiagram, add_teacher_systems, close_policy_loop
from corn_drake.scene.builder import Scene
from corn_drake.timing import clock_of
from corn_drake.scene.objects import ObjectSpec
from corn_drake.systems.perception.cameras import CameraRig, add_camera_rig, remove_perception_role
from corn_drake.systems.perception.pose_tracker import PoseTracker
from corn_drake.systems.perception.segmentation import ObjectSegmentation, robot_link_primitives
from corn_drake.systems.student_observations import StudentObservations


@dataclasses.dataclass
class PerceptionHandles:
    rig: CameraRig
    segmentation: ObjectSegmentation
    tracker: PoseTracker


@dataclasses.dataclass
class StudentDiagram:
    diagram: Diagram
    teacher: TeacherDiagram
    perception: PerceptionHandles
    observations: StudentObservations
    config: StudentDiagramConfig

    @property
    def scene(self) -> Scene:
        return self.teacher.scene

    @property
    def policy(self):
        """The StudentPolicySystem of an evaluation diagram (None in a rollout diagram)."""
        return self.teacher.policy


def _pose7_selector() -> np.ndarray:
    """POSE7_DIM x FREE_BODY_STATE_DIM matrix: a free body's state -> its pose7."""
    S = np.zeros((POSE7_DIM, FREE_BODY_STATE_DIM))
    S[POSE7_POSITION, FREE_BODY_POSITION] = np.eye(3)
    S[POSE7_QUATERNION, FREE_BODY_QUATERNION] = np.eye(4)
    return S


def add_perception_systems(builder: DiagramBuilder, scene: Scene, cfg: StudentDiagramConfig,
                           goal_pose_port=None) -> PerceptionHandles:
    """Cameras -> segmentation -> tracker on `scene` (whose plant is already finalized)."""
    plant, sg = scene.plant, scene.scene_graph
    object_state = plant.get_state_output_port(scene.object_instance)
    robot_state = plant.get_state_output_port(scene.panda)
    if cfg.cameras.hide_robot:
        visuals = [g for b in plant.GetBodyIndices(scene.panda)
                   for g in plant.GetVisualGeometriesForBody(plant.get_body(b))]
        remove_perception_role(plant, sg, visuals)
    rig = add_camera_rig(builder, sg, cfg.cameras, scene.object_spec.radius, object_state)

    seg_cfg = cfg.segmentation
    geometric = seg_cfg.mode == "geometric"
    seg = builder.AddNamedSystem("segmentation", ObjectSegmentation(
        seg_cfg, len(rig.sensors), table_size=scene.config.table_size,
        robot_base=scene.config.robot_base,
        prims=robot_link_primitives(plant, sg, scene.panda) if geometric else None,
        object_label=int(scene.object_body.index()), px_per_m=rig.px_per_m))
    for i, port in enumerate(rig.cloud_ports()):
        builder.Connect(port, seg.GetInputPort(f"cloud{i}"))
    if geometric:
        builder.Connect(robot_state, seg.GetInputPort("robot_state"))
    else:
        for i, port in enumerate(rig.label_ports()):
            builder.Connect(port, seg.GetInputPort(f"label{i}"))

    # One estimate per policy step, between its last plant update and the policy's latch.
    clock = clock_of(cfg.teacher.scene.physics)
    tracker = builder.AddNamedSystem("pose_tracker", PoseTracker(
        cfg.tracker, period=clock.period, offset=clock.perception_offset,
        thin=scene.object_spec.thin))
    builder.Connect(seg.GetOutputPort("object_cloud"), tracker.GetInputPort("object_cloud"))
    # The tracker starts from the true initial pose (on the robot: the pose the episode is
    # set up at); afterwards it only sees clouds.
    to_pose7 = builder.AddNamedSystem("object_pose7", MatrixGain(_pose7_selector()))
    builder.Connect(object_state, to_pose7.get_input_port())
    builder.Connect(to_pose7.get_output_port(), tracker.GetInputPort("initial_pose"))
    if goal_pose_port is not None:
        builder.Connect(goal_pose_port, tracker.GetInputPort("goal_pose"))
    return PerceptionHandles(rig=rig, segmentation=seg, tracker=tracker)


def build_student_diagram(cfg: StudentDiagramConfig | None = None, spec: ObjectSpec | None = None,
                          meshcat=None, student=None,
                          stochastic_policy: bool = False) -> StudentDiagram:
    """The student rollout diagram; the action is the exported input `controller.action`.

    With `student` (a StudentPolicy in eval mode), a StudentPolicySystem named "policy" reads
    the student observations and closes the loop inside the diagram instead (the student's
    evaluation diagram) and there is no action input; with `stochastic_policy` it samples its
    actions (diagrams.close_policy_loop)."""
    if stochastic_policy and student is None:
        raise ValueError("stochastic_policy needs a student: without one the action is an input")
    cfg = cfg or load_student_config()
    cfg.check()
    builder = DiagramBuilder()
    teacher = add_teacher_systems(builder, cfg.teacher, spec)
    if student is None:
        builder.ExportInput(teacher.ik.GetInputPort("action"), "controller.action")
    perception = add_perception_systems(builder, teacher.scene, cfg,
                                        teacher.sources["goal_pose"].get_output_port())
    n = cfg.segmentation.num_points
    obs = builder.AddNamedSystem("student_observations", StudentObservations(
        n, cfg.observation.cloud_noise_std, cfg.observation.goal_noise_std))
    # New samples every policy period; reseed_random_sources gives each episode fresh seeds.
    period = cfg.teacher.scene.physics.policy_period
    for name, size, port in (("cloud_noise", 3 * n, "cloud_unit_noise"),
                             ("goal_noise", 3, "goal_unit_noise")):
        noise = builder.AddNamedSystem(name, RandomSource(RandomDistribution.kGaussian, size, period))
        builder.Connect(noise.get_output_port(), obs.GetInputPort(port))
    builder.Connect(perception.segmentation.GetOutputPort("points"), obs.GetInputPort("points"))
    builder.Connect(teacher.observations.GetOutputPort("hand_state"), obs.GetInputPort("hand_state"))
    builder.Connect(teacher.scene.plant.get_state_output_port(teacher.scene.panda),
                    obs.GetInputPort("robot_state"))
    builder.Connect(teacher.ik.GetOutputPort("previous_action"), obs.GetInputPort("previous_action"))
    builder.Connect(perception.tracker.GetOutputPort("goal"), obs.GetInputPort("estimated_goal"))
    for key in STUDENT_OBS_KEYS:
        builder.ExportOutput(obs.GetOutputPort(key), f"student.{key}")
    if student is not None:
        # torch: only here
        from corn_drake.systems.policies.student_policy import (StudentPolicySystem)

        policy = builder.AddNamedSystem("policy", StudentPolicySystem(
            student, n, clock_of(cfg.teacher.scene.physics), stochastic_policy))
        for key in STUDENT_OBS_KEYS:
            builder.Connect(obs.GetOutputPort(key), policy.GetInputPort(key))
        close_policy_loop(builder, teacher, policy, stochastic_policy)
    builder.ExportOutput(perception.tracker.GetOutputPort("pose"), "perception.pose")
    builder.ExportOutput(perception.tracker.GetOutputPort("status"), "perception.status")
    builder.ExportOutput(perception.segmentation.GetOutputPort("num_points"), "perception.num_points")
    builder.ExportOutput(perception.segmentation.GetOutputPort("object_cloud"),
                         "perception.object_cloud")
    if meshcat is not None:
        from corn_drake.viz.meshcat import add_meshcat_visualizer

        add_meshcat_visualizer(builder, teacher.scene.scene_graph, meshcat)
    diagram = builder.Build()
    diagram.set_name("student_rollout")
    teacher.diagram = diagram
    return StudentDiagram(diagram=diagram, teacher=teacher, perception=perception,
                          observations=obs, config=cfg)
