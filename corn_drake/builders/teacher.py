"""Builders that turn the typed YAML configs in diagrams/ into Drake Diagrams.

Teacher diagram: plant + scene graph, ActionToJointTargets -> VariableImpedanceController ->
plant, TeacherObservations and TaskReward, with the per-episode quantities (goal pose, physics
parameters, object cloud, keypoints and radius) held as ConstantVectorSource parameters in the
context, so reset re-randomizes without rebuilding anything.

Exported ports: input `controller.action`; outputs `obs.<key>` for each observation key,
`task.reward`, `task.status`, `plant.object_state`, `plant.robot_state`.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.common import RandomDistribution, RandomGenerator
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, RandomSource, ZeroOrderHold

from corn_drake.config.scene import ObjectConfig
from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.contract import ACTION_DIM, NUM_JOINTS
from corn_drake.errors import InputError
from corn_drake.config.plumbing.diagram_files import load_teacher_config
from corn_drake.scene.builder import Scene, build_scene
from corn_drake.scene.objects import ObjectSpec, box_spec, cylinder_spec
from corn_drake.scene.randomization import apply_physics
from corn_drake.systems.control.energy_meter import add_energy_meter
from corn_drake.systems.control.ik import ActionToJointTargets
from corn_drake.systems.control.impedance_controller import make_impedance_controller
from corn_drake.systems.observations import OBS_KEYS, TeacherObservations
from corn_drake.systems.reward import TaskReward, add_task_reward, reset_previous
from corn_drake.tasks.episode import Episode
from corn_drake.timing import clock_of


@dataclasses.dataclass
class TeacherDiagram:
    diagram: Diagram
    scene: Scene
    ik: ActionToJointTargets
    controller: object  # VariableImpedanceController or its symbolic twin (same ports)
    observations: TeacherObservations
    reward: TaskReward
    reward_hold: ZeroOrderHold  # the previous policy step's [object_state, hand_state, energy]
    # Per-episode parameter sources, keyed by name (goal_pose, physics_params, object_cloud,
    # object_keypoints, object_radius, torque_noise_std).
    sources: dict[str, ConstantVectorSource]
    config: TeacherDiagramConfig
    cloud_indices: np.ndarray  # which rows of the object's cloud the observation uses
    policy: object = None  # the PolicySystem of an evaluation diagram
    # (diagram, its default context): what write_episode restores before each episode.
    _default: tuple = dataclasses.field(default=(None, None), repr=False)

    def write_episode(self, context, episode: Episode, rng: np.random.Generator) -> None:
        """Writes `episode` into `context`, the root context of `self.diagram` (the teacher
        diagram, or the student diagram built around these systems): the default context at the
        policy clock's first boundary, the sampled physics, robot joints and object pose, the
        per-episode sources, fresh seeds for every RandomSource from `rng`, the IK latch holding
        the start joints and the reward's previous-step hold at the start state. Call
        Simulator.Initialize() after."""
        root = self.diagram
        if self._default[0] is not root:
            self._default = (root, root.CreateDefaultContext())
        scene, spec, phys = self.scene, self.scene.object_spec, episode.physics
        context.SetTimeStateAndParametersFrom(self._default[1])
        context.SetTime(clock_of(self.config.scene.physics).boundary(0))
        apply_physics(scene, phys, context, 1.0)  # the default context holds the unscaled shapes
        plant_context = scene.plant.GetMyMutableContextFromRoot(context)
        scene.plant.SetPositions(plant_context, scene.panda, episode.initial_joints)
        start = episode.initial_object_pose
        scene.plant.SetFreeBodyPose(plant_context, scene.object_body, RigidTransform(
            Quaternion(start[3:] / np.linalg.norm(start[3:])), start[:3]))
        s = phys.scale
        for name, value in (("goal_pose", episode.goal_pose),
                            ("physics_params", phys.as_observation()),
                            ("object_cloud", s * spec.cloud[self.cloud_indices, :3].reshape(-1)),
                            ("object_keypoints", s * spec.bbox_corners.reshape(-1)),
                            ("object_radius", [s * spec.radius]),
                            ("torque_noise_std", [phys.torque_noise_std])):
            source = self.sources[name]
            source.get_mutable_source_value(source.GetMyMutableContextFromRoot(context)).set_value(
                np.asarray(value, float))
        # After the episode's draws, so a seed gives the same episode with or without noise.
        reseed_random_sources(root, context, rng)
        self.ik.hold_position(self.ik.GetMyMutableContextFromRoot(context), episode.initial_joints)
        reset_previous(self.reward_hold, self.reward, context)


def object_spec_from_config(cfg: ObjectConfig, seed: int = 0) -> ObjectSpec:
    """The one object `cfg` names (a diagram holds one object; EnvFactory picks one per episode
    from a config naming all train objects of a library)."""
    if cfg.cycles_library:
        raise InputError(f"scene.object names every train object of library {cfg.library} "
                         "(library_objects: train): a diagram holds one; set library_objects: "
                         "one and an object_id")
    if cfg.kind == "box":
        return box_spec(cfg.size, cfg.mass, seed=seed)
    if cfg.kind == "cylinder":
        return cylinder_spec(cfg.radius, cfg.length, cfg.mass, seed=seed)
    from corn_drake.assets.library import load_object_spec

    return load_object_spec(cfg.library, cfg.object_id)


def reseed_random_sources(diagram: Diagram, context, rng: np.random.Generator) -> int:
    """Draws a fresh seed from `rng` for every RandomSource in `diagram` (torque noise, the
    student's cloud and goal noise); returns how many. Call it after restoring a default
    context: that context holds each source's construction-time seed, so without this every
    episode (and every Ray worker, which builds its sources in the same order) replays one noise
    sequence. Only the sources: the diagram's own SetRandomContext would re-randomize any
    other system that declares random state or parameters as well."""
    count = 0
    for system in diagram.GetSystems():
        if isinstance(system, RandomSource):
            system.SetRandomContext(system.GetMyMutableContextFromRoot(context),
                                    RandomGenerator(int(rng.integers(2 ** 32))))
            count += 1
    return count


def add_teacher_systems(builder: DiagramBuilder, cfg: TeacherDiagramConfig,
                        spec: ObjectSpec | None = None) -> TeacherDiagram:
    """Adds the teacher scene and systems to `builder` (for diagrams that add more systems)."""
    spec = spec or object_spec_from_config(cfg.scene.object, cfg.seed)
    scene = build_scene(builder, cfg.scene, spec)
    plant, physics = scene.plant, cfg.scene.physics
    n_pts = cfg.scene.object.cloud_points
    # A fixed subset of the object's surface samples: the cloud moves rigidly with the object,
    # so patch indices can be computed once per object downstream.
    cloud_indices = np.random.default_rng(cfg.seed).choice(len(spec.cloud), n_pts,
                                                           replace=len(spec.cloud) < n_pts)

    def source(name, value):
        s = builder.AddNamedSystem(name, ConstantVectorSource(np.asarray(value, float)))
        return s

    sources = {
        "goal_pose": source("goal_pose", spec.stable_poses[0]),
        "physics_params": source("physics_params", np.zeros(5)),
        "object_cloud": source("object_cloud", spec.cloud[cloud_indices, :3].reshape(-1)),
        "object_keypoints": source("object_keypoints", spec.bbox_corners.reshape(-1)),
        "object_radius": source("object_radius", [spec.radius]),
        "torque_noise_std": source("torque_noise_std", [0.0]),
    }
    robot_state = plant.get_state_output_port(scene.panda)
    object_state = plant.get_state_output_port(scene.object_instance)

    ik = builder.AddNamedSystem("ik", ActionToJointTargets(
        cfg.controller, clock_of(physics), np.asarray(cfg.scene.robot_base), physics.armature))
    with_noise = cfg.randomization.torque_noise_std > 0
    ctrl = builder.AddNamedSystem("controller", make_impedance_controller(
        cfg.controller.effort_limits, with_noise, cfg.controller.torque_backend))
    builder.Connect(robot_state, ik.GetInputPort("robot_state"))
    builder.Connect(object_state, ik.GetInputPort("object_state"))
    builder.Connect(sources["object_radius"].get_output_port(), ik.GetInputPort("object_radius"))
    builder.Connect(robot_state, ctrl.GetInputPort("robot_state"))
    builder.Connect(ik.GetOutputPort("q_target"), ctrl.GetInputPort("q_target"))
    builder.Connect(ik.GetOutputPort("gains"), ctrl.GetInputPort("gains"))
    builder.Connect(sources["torque_noise_std"].get_output_port(), ctrl.GetInputPort("noise_std"))
    builder.Connect(ctrl.GetOutputPort("actuation"), plant.get_actuation_input_port(scene.panda))
    if with_noise:
        noise = builder.AddNamedSystem("torque_noise", RandomSource(
            RandomDistribution.kGaussian, NUM_JOINTS, physics.time_step))
        builder.Connect(noise.get_output_port(), ctrl.GetInputPort("unit_noise"))

    obs = builder.AddNamedSystem("observations", TeacherObservations(n_pts, cfg.scene.robot_base))
    builder.Connect(robot_state, obs.GetInputPort("robot_state"))
    builder.Connect(object_state, obs.GetInputPort("object_state"))
    builder.Connect(ik.GetOutputPort("previous_action"), obs.GetInputPort("previous_action"))
    for name in ("goal_pose", "physics_params", "object_cloud"):
        builder.Connect(sources[name].get_output_port(), obs.GetInputPort(name))
    builder.Connect(sources["object_keypoints"].get_output_port(), obs.GetInputPort("object_corners"))

    if cfg.task.energy_coef != 0:
        energy, _ = add_energy_meter(builder, plant.get_net_actuation_output_port(scene.panda),
                                     robot_state, physics.time_step)
    else:
        # No penalty, no meter: it is a symbolic discrete update behind a multiplexer at every
        # physics step (with the symbolic torque law, ~5 % of an env step in a perf profile
        # here), and the reward would only multiply its sum by zero.
        energy = source("energy_unused", [0.0]).get_output_port()
    reward, reward_hold = add_task_reward(builder, cfg.task, clock_of(physics), object_state,
                                          obs.GetOutputPort("hand_state"), energy)
    builder.Connect(sources["goal_pose"].get_output_port(), reward.GetInputPort("goal_pose"))
    builder.Connect(sources["object_keypoints"].get_output_port(),
                    reward.GetInputPort("object_keypoints"))

    builder.ExportOutput(robot_state, "plant.robot_state")
    builder.ExportOutput(object_state, "plant.object_state")
    builder.ExportOutput(obs.GetOutputPort("observation"), "obs.observation")
    for key in OBS_KEYS:
        builder.ExportOutput(obs.GetOutputPort(key), f"obs.{key}")
    builder.ExportOutput(reward.GetOutputPort("reward"), "task.reward")
    builder.ExportOutput(reward.GetOutputPort("task_status"), "task.status")
    return TeacherDiagram(diagram=None, scene=scene, ik=ik, controller=ctrl, observations=obs,
                          reward=reward, reward_hold=reward_hold, sources=sources, config=cfg,
                          cloud_indices=cloud_indices)


def close_policy_loop(builder: DiagramBuilder, handles: TeacherDiagram, policy,
                      stochastic: bool) -> None:
    """Feeds `policy`'s `action` output (a PolicySystem or the student's StudentPolicySystem,
    its observations already connected) to the IK latch and records it in `handles.policy`.
    A stochastic policy gets its `unit_noise` from a RandomSource named "policy_noise": a fresh
    N(0, 1) draw every policy period, seeded per episode by reseed_random_sources."""
    builder.Connect(policy.GetOutputPort("action"), handles.ik.GetInputPort("action"))
    if stochastic:
        noise = builder.AddNamedSystem("policy_noise", RandomSource(
            RandomDistribution.kGaussian, ACTION_DIM, clock_of(handles.config.scene.physics).period))
        builder.Connect(noise.get_output_port(), policy.GetInputPort("unit_noise"))
    handles.policy = policy


def build_teacher_diagram(cfg: TeacherDiagramConfig | None = None, spec: ObjectSpec | None = None,
                          meshcat=None, agent=None, stochastic_policy: bool = False,
                          attention: bool = False) -> TeacherDiagram:
    """The teacher rollout diagram; the action is the exported input `controller.action`.

    With `agent` (a TeacherAgent), a PolicySystem closes the loop inside the diagram instead
    (the evaluation diagram, `corn-drake evaluate`) and there is no action input. With
    `stochastic_policy`, it samples its actions: a RandomSource named "policy_noise" feeds it
    N(0, 1) draws, a fresh one every policy period (reseed_random_sources seeds it per episode).
    With `attention` (an agent that cross-attends, and a meshcat), the PolicySystem also
    outputs its attention and an AttentionView named "attention_view" paints it on the object's
    cloud in Meshcat every policy step (viz/attention_view.py).
    """
    from corn_drake.systems.policies.policy import PolicySystem

    if stochastic_policy and agent is None:
        raise ValueError("stochastic_policy needs an agent: without one the action is an input")
    if attention and (agent is None or meshcat is None):
        raise ValueError("attention needs an agent (whose attention is shown) and a meshcat "
                         "(where it is drawn)")
    cfg = cfg or load_teacher_config()
    builder = DiagramBuilder()
    handles = add_teacher_systems(builder, cfg, spec)
    if agent is None:
        builder.ExportInput(handles.ik.GetInputPort("action"), "controller.action")
    else:
        policy = builder.AddNamedSystem("policy", PolicySystem(
            agent, cfg.scene.object.cloud_points, stochastic=stochastic_policy,
            attention=attention))
        builder.Connect(handles.observations.GetOutputPort("observation"),
                        policy.GetInputPort("observation"))
        close_policy_loop(builder, handles, policy, stochastic_policy)
    if meshcat is not None:
        from corn_drake.viz.meshcat import add_meshcat_visualizer

        add_meshcat_visualizer(builder, handles.scene.scene_graph, meshcat)
        if attention:
            from corn_drake.viz.attention_view import add_attention_view

            add_attention_view(builder, handles.policy, handles.observations.GetOutputPort("cloud"),
                               meshcat, cfg.scene.object.cloud_points, clock_of(cfg.scene.physics))
    handles.diagram = builder.Build()
    handles.diagram.set_name("teacher_rollout")
    return handles
