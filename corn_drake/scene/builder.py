"""The scene: MultibodyPlant + SceneGraph with the Panda, the table and one free object."""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.geometry import (AddCompliantHydroelasticProperties, AddContactMaterial,
                              AddRigidHydroelasticProperties, Box, CollisionFilterDeclaration,
                              Convex, Cylinder, GeometryId, GeometrySet, ProximityProperties,
                              SceneGraph)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex, RigidBody, SpatialInertia, UnitInertia
from pydrake.systems.framework import DiagramBuilder

from corn_drake.config.scene import SceneConfig
from corn_drake.scene.franka import FINGER_BODIES, add_franka
from corn_drake.scene.friction import geometry_friction
from corn_drake.scene.objects import TABLE_TOP_Z, ObjectSpec

OBJECT_NAME = "object"
TABLE_NAME = "table"
# Nominal frictions in the paper's (averaging) terms; the geometries get Drake's equivalents.
DEFAULT_TABLE_FRICTION = 0.5
DEFAULT_OBJECT_FRICTION = 0.8
DEFAULT_FINGER_FRICTION = 1.0
_DEFAULT_GEOMETRY_FRICTION = geometry_friction(DEFAULT_OBJECT_FRICTION, DEFAULT_TABLE_FRICTION,
                                               DEFAULT_FINGER_FRICTION)


@dataclasses.dataclass
class Scene:
    plant: MultibodyPlant
    scene_graph: SceneGraph
    panda: ModelInstanceIndex
    object_instance: ModelInstanceIndex
    object_body: RigidBody
    object_spec: ObjectSpec
    object_geometries: list[GeometryId]
    table_geometries: list[GeometryId]
    finger_geometries: list[GeometryId]
    robot_geometries: list[GeometryId]
    config: SceneConfig


def friction_properties(mu: float) -> ProximityProperties:
    props = ProximityProperties()
    AddContactMaterial(friction=CoulombFriction(mu, mu), properties=props)
    return props


def _check_compliant_body(cfg: SceneConfig) -> str:
    if cfg.physics.compliant_body not in ("object", "table"):
        raise ValueError(f"physics.compliant_body must be 'object' or 'table', "
                         f"got {cfg.physics.compliant_body!r}")
    return cfg.physics.compliant_body


def object_proximity_properties(cfg: SceneConfig, mu: float) -> ProximityProperties:
    props = ProximityProperties()
    AddContactMaterial(dissipation=cfg.physics.object_hunt_crossley_dissipation,
                       friction=CoulombFriction(mu, mu), properties=props)
    # One side of object-table contact is compliant, so a resting object gets a contact patch
    # instead of a single rocking point (measured: point contact rocked 0.09 rad in 1 s).
    if _check_compliant_body(cfg) == "object":
        AddCompliantHydroelasticProperties(
            resolution_hint=0.01, hydroelastic_modulus=cfg.physics.object_hydroelastic_modulus,
            properties=props)
    else:
        AddRigidHydroelasticProperties(0.01, props)  # the hint meshes rigid primitives
    return props


def table_proximity_properties(cfg: SceneConfig, mu: float) -> ProximityProperties:
    props = friction_properties(mu)
    if _check_compliant_body(cfg) == "table":
        AddCompliantHydroelasticProperties(
            resolution_hint=cfg.physics.table_resolution_hint,
            hydroelastic_modulus=cfg.physics.table_hydroelastic_modulus, properties=props)
    else:
        AddRigidHydroelasticProperties(props)
    return props


def object_shapes(spec: ObjectSpec, scale: float = 1.0):
    if spec.primitive is not None:
        kind, dims = spec.primitive
        if kind == "box":
            return [Box(*(scale * np.asarray(dims)))]
        if kind == "cylinder":
            return [Cylinder(scale * dims[0], scale * dims[1])]
        raise ValueError(f"object {spec.name}: unknown primitive {kind!r}")
    return [Convex(str(p), scale) for p in spec.hull_paths]


def _add_table(plant: MultibodyPlant, cfg: SceneConfig) -> list[GeometryId]:
    size = np.asarray(cfg.table_size, float)
    X = RigidTransform([0.0, 0.0, TABLE_TOP_Z - size[2] / 2])
    props = table_proximity_properties(cfg, _DEFAULT_GEOMETRY_FRICTION.table)
    shape = Box(*size)
    gid = plant.RegisterCollisionGeometry(plant.world_body(), X, shape, TABLE_NAME, props)
    plant.RegisterVisualGeometry(plant.world_body(), X, shape, TABLE_NAME, [0.55, 0.4, 0.3, 1.0])
    return [gid]


def _add_object(plant: MultibodyPlant, cfg: SceneConfig, spec: ObjectSpec):
    instance = plant.AddModelInstance(OBJECT_NAME)
    inertia = SpatialInertia(spec.mass, spec.com, UnitInertia(*np.diag(spec.unit_inertia),
                                                               *spec.unit_inertia[[0, 0, 1], [1, 2, 2]]))
    body = plant.AddRigidBody(OBJECT_NAME, instance, inertia)
    props = object_proximity_properties(cfg, _DEFAULT_GEOMETRY_FRICTION.object)
    gids = []
    for i, shape in enumerate(object_shapes(spec)):
        gids.append(plant.RegisterCollisionGeometry(body, RigidTransform(), shape,
                                                    f"{OBJECT_NAME}_hull{i}", props))
    visual = Convex(str(spec.visual_path)) if spec.visual_path else None
    for i, shape in enumerate([visual] if visual else object_shapes(spec)):
        plant.RegisterVisualGeometry(body, RigidTransform(), shape, f"{OBJECT_NAME}_visual{i}",
                                     [0.2, 0.5, 0.85, 1.0])
    return instance, body, gids


def build_table_scene(builder: DiagramBuilder, cfg: SceneConfig, spec: ObjectSpec):
    """Table + the free object only (no robot): for drop tests of stable poses.

    Returns (plant, scene_graph, object body); the plant is finalized.
    """
    plant, scene_graph = AddMultibodyPlant(cfg.physics.plant, builder)
    _add_table(plant, cfg)
    _, body, _ = _add_object(plant, cfg, spec)
    plant.Finalize()
    return plant, scene_graph, body


def build_scene(builder: DiagramBuilder, cfg: SceneConfig, spec: ObjectSpec) -> Scene:
    """Adds plant + scene graph to `builder`; the plant is finalized on return."""
    # Drake's plant settings as the config holds them (config/scene.py says why its ports are unsampled).
    plant, scene_graph = AddMultibodyPlant(cfg.physics.plant, builder)
    panda = add_franka(plant, RigidTransform(cfg.robot_base), cfg.physics.armature)
    if not cfg.physics.gravity_on_robot:
        # As in the paper's simulation: the torque law has no gravity term.
        plant.set_gravity_enabled(panda, False)
    table_gids = _add_table(plant, cfg)
    instance, body, object_gids = _add_object(plant, cfg, spec)
    plant.Finalize()

    robot_gids = [g for b in plant.GetBodyIndices(panda)
                  for g in plant.GetCollisionGeometriesForBody(plant.get_body(b))]
    finger_gids = [g for name in FINGER_BODIES
                   for g in plant.GetCollisionGeometriesForBody(plant.GetBodyByName(name, panda))]
    # The arm never needs to collide with itself; skipping those pairs saves contact queries.
    scene_graph.collision_filter_manager().Apply(
        CollisionFilterDeclaration().ExcludeWithin(GeometrySet(robot_gids)))
    return Scene(plant=plant, scene_graph=scene_graph, panda=panda, object_instance=instance,
                 object_body=body, object_spec=spec, object_geometries=object_gids,
                 table_geometries=table_gids, finger_geometries=finger_gids,
                 robot_geometries=robot_gids, config=cfg)
