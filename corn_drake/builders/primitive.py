"""The contact-primitive rollout diagram: the teacher diagram's systems with a PrimitiveExecutor
driving the IK latch's action input where a PolicySystem would.

  observations -> executor (action) -> IK latch -> controller -> plant
  plant (object state) -> ObjectSurface (world normals, object position)
Without an agent the primitive is an exported input, `executor.primitive` (the gymnasium env
fixes it, one primitive per env step); with one, a PrimitivePolicySystem named "policy"
chooses each primitive from the observation when the executor asks for one (the evaluation
diagram). With a Meshcat, the chosen contact point, the push arrow and the policy's scores over
its locations are drawn every policy step (viz/primitive_view.py), live and in recordings.

Exported ports besides the teacher diagram's outputs: `executor.status` (STATUS_DIM),
`object.normals` (N x 3), `object.position` (3).
"""

from __future__ import annotations

import dataclasses

from pydrake.systems.framework import DiagramBuilder

from corn_drake.builders.teacher import TeacherDiagram, add_teacher_systems
from corn_drake.config.primitive import PrimitiveConfig
from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.scene.objects import ObjectSpec
from corn_drake.systems.object_surface import ObjectSurface
from corn_drake.systems.control.primitive_executor import PrimitiveExecutor
from corn_drake.timing import clock_of


@dataclasses.dataclass
class PrimitiveDiagram:
    teacher: TeacherDiagram  # its `diagram` is the whole primitive diagram
    executor: PrimitiveExecutor
    surface: ObjectSurface
    policy: object = None  # the PrimitivePolicySystem of an evaluation diagram


def build_primitive_diagram(cfg: TeacherDiagramConfig, primitive: PrimitiveConfig,
                            spec: ObjectSpec | None = None, meshcat=None,
                            agent=None) -> PrimitiveDiagram:
    builder = DiagramBuilder()
    teacher = add_teacher_systems(builder, cfg, spec)
    scene, clock = teacher.scene, clock_of(cfg.scene.physics)
    num_points = cfg.scene.object.cloud_points
    executor = builder.AddNamedSystem("executor", PrimitiveExecutor(
        primitive, cfg.controller, clock, num_points))
    builder.Connect(teacher.observations.GetOutputPort("observation"),
                    executor.GetInputPort("observation"))
    builder.Connect(executor.GetOutputPort("action"), teacher.ik.GetInputPort("action"))
    surface = builder.AddNamedSystem("object_surface", ObjectSurface(
        scene.object_spec.cloud[teacher.cloud_indices, 3:]))
    builder.Connect(scene.plant.get_state_output_port(scene.object_instance),
                    surface.GetInputPort("object_state"))
    handles = PrimitiveDiagram(teacher=teacher, executor=executor, surface=surface)
    if agent is None:
        builder.ExportInput(executor.GetInputPort("primitive"), "executor.primitive")
    else:
        from corn_drake.systems.policies.primitive_policy import PrimitivePolicySystem

        policy = builder.AddNamedSystem("policy", PrimitivePolicySystem(agent, num_points, clock))
        for port, source in (("observation", teacher.observations.GetOutputPort("observation")),
                             ("normals", surface.GetOutputPort("normals")),
                             ("object_position", surface.GetOutputPort("position")),
                             ("executor_status", executor.GetOutputPort("status"))):
            builder.Connect(source, policy.GetInputPort(port))
        builder.Connect(policy.GetOutputPort("primitive"), executor.GetInputPort("primitive"))
        handles.policy = teacher.policy = policy
    builder.ExportOutput(executor.GetOutputPort("status"), "executor.status")
    builder.ExportOutput(surface.GetOutputPort("normals"), "object.normals")
    builder.ExportOutput(surface.GetOutputPort("position"), "object.position")
    if meshcat is not None:
        from corn_drake.viz.meshcat import add_meshcat_visualizer
        from corn_drake.viz.primitive_view import add_primitive_view

        add_meshcat_visualizer(builder, scene.scene_graph, meshcat)
        add_primitive_view(builder, handles, meshcat, clock)
    teacher.diagram = builder.Build()
    teacher.diagram.set_name("primitive_rollout")
    return handles
