"""Per-episode domain randomization applied through the context (no diagram rebuild).

Mass and inertia are plant parameters; friction lives in the proximity properties that SceneGraph
keeps in its context (AssignRole with kReplace); object scale swaps the object's shapes in the
SceneGraph context (ChangeShape) and rescales inertia, cloud, keypoints and stable poses.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.geometry import (AddRigidHydroelasticProperties, ProximityProperties, RoleAssign)
from pydrake.multibody.tree import SpatialInertia, UnitInertia

from corn_drake.config.scene import RandomizationConfig
from corn_drake.scene.builder import (DEFAULT_FINGER_FRICTION, DEFAULT_OBJECT_FRICTION,
                                      DEFAULT_TABLE_FRICTION, Scene, friction_properties,
                                      object_proximity_properties, object_shapes,
                                      table_proximity_properties)
from corn_drake.scene.friction import geometry_friction
from corn_drake.scene.objects import TABLE_TOP_Z


@dataclasses.dataclass
class PhysicsSample:
    """Sampled physics in the paper's terms: a friction here is one surface's coefficient under
    the paper's average combination (scene/friction.py writes Drake's equivalents)."""
    mass: float
    scale: float
    object_friction: float
    table_friction: float
    finger_friction: float
    restitution: float
    torque_noise_std: float

    def as_observation(self) -> np.ndarray:
        """The 5 physics parameters the teacher observes."""
        return np.array([self.mass, self.table_friction, self.object_friction,
                         self.finger_friction, self.restitution])


def nominal_sample(scene: Scene) -> PhysicsSample:
    return PhysicsSample(mass=scene.object_spec.mass, scale=1.0,
                         object_friction=DEFAULT_OBJECT_FRICTION,
                         table_friction=DEFAULT_TABLE_FRICTION,
                         finger_friction=DEFAULT_FINGER_FRICTION, restitution=0.0,
                         torque_noise_std=0.0)


def sample_physics(cfg: RandomizationConfig, scene: Scene, rng: np.random.Generator) -> PhysicsSample:
    if not cfg.enabled:
        return nominal_sample(scene)

    def u(r):
        return float(rng.uniform(r[0], r[1]))

    cfg.check()
    scale = 1.0
    if cfg.object_radius is not None:
        scale = u(cfg.object_radius) / scene.object_spec.radius
    return PhysicsSample(mass=u(cfg.mass), scale=scale, object_friction=u(cfg.object_friction),
                         table_friction=u(cfg.table_friction),
                         finger_friction=u(cfg.finger_friction), restitution=u(cfg.restitution),
                         torque_noise_std=cfg.torque_noise_std)


def _rigid_props(mu: float) -> ProximityProperties:
    props = friction_properties(mu)
    AddRigidHydroelasticProperties(props)
    return props


def apply_physics(scene: Scene, sample: PhysicsSample, root_context, current_scale: float) -> None:
    """Writes `sample` into the diagram context. `current_scale` is the scale now in the context."""
    plant, sg = scene.plant, scene.scene_graph
    plant_ctx = plant.GetMyMutableContextFromRoot(root_context)
    sg_ctx = sg.GetMyMutableContextFromRoot(root_context)
    spec = scene.object_spec
    s = sample.scale
    unit = spec.unit_inertia * s * s  # unit inertia scales with length squared
    scene.object_body.SetSpatialInertiaInBodyFrame(plant_ctx, SpatialInertia(
        sample.mass, spec.com * s, UnitInertia(*np.diag(unit), *unit[[0, 0, 1], [1, 2, 2]])))
    source = plant.get_source_id()
    if abs(s - current_scale) > 1e-12:
        for gid, shape in zip(scene.object_geometries, object_shapes(spec, s)):
            sg.ChangeShape(sg_ctx, source, gid, shape)
    mu = geometry_friction(sample.object_friction, sample.table_friction, sample.finger_friction)
    obj_props = object_proximity_properties(scene.config, mu.object)
    for gid in scene.object_geometries:
        sg.AssignRole(sg_ctx, source, gid, obj_props, RoleAssign.kReplace)
    table_props = table_proximity_properties(scene.config, mu.table)
    for gid in scene.table_geometries:
        sg.AssignRole(sg_ctx, source, gid, table_props, RoleAssign.kReplace)
    for gid in scene.finger_geometries:
        sg.AssignRole(sg_ctx, source, gid, _rigid_props(mu.finger), RoleAssign.kReplace)


def scaled_stable_poses(poses: np.ndarray, scale: float) -> np.ndarray:
    """Stable poses of the object scaled about its frame origin: heights scale above the table."""
    out = poses.copy()
    out[:, 2] = TABLE_TOP_Z + (poses[:, 2] - TABLE_TOP_Z) * scale
    return out
