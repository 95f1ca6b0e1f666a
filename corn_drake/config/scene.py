"""Typed configs of the scene: physics, the object, domain randomization, the controller.

Numbers default to the paper's / official code's values (see ../shared/DESIGN.md spec sheet).
No `from __future__ import annotations`: yaml_load_typed needs real types on the fields.
"""

import dataclasses as dc
import typing

from pydrake.multibody.plant import MultibodyPlantConfig

from corn_drake.config.plumbing.bounds import one_of, relation
from corn_drake.config.choices import (COMPLIANT_BODIES, CONTACT_MODELS,
                                       CONTACT_SURFACE_REPRESENTATIONS,
                                       DISCRETE_CONTACT_APPROXIMATIONS, TORQUE_BACKENDS)
from corn_drake.config.plumbing.yaml_io import pickle_as_yaml
from corn_drake.contract import NUM_JOINTS
from corn_drake.errors import InputError
from corn_drake.timing import whole_multiple


def _plant_config() -> MultibodyPlantConfig:
    return MultibodyPlantConfig(
        # 80 Hz physics / 10 Hz policy as in the paper; tests/test_scene_physics.py checks
        # resting and pushing stability at this step.
        time_step=0.0125,
        discrete_contact_approximation="sap",
        contact_model="hydroelastic_with_fallback",
        # Unsampled output ports: every system that updates at a policy boundary t_k (IK latch,
        # reward hold) then sees the plant state at t_k. With sampled ports (Drake's default)
        # they saw the state one physics step later, because the plant's own update at t_k had
        # already been computed (tests/test_reward.py checks the hold).
        use_sampled_output_ports=False)


@dc.dataclass
class PhysicsConfig:
    # Range checks (config/plumbing/bounds.py): what check_bounds refuses.
    BOUNDS = {
              "policy_period": "> 0", "object_hydroelastic_modulus": "> 0",
              "table_hydroelastic_modulus": "> 0", "table_resolution_hint": "> 0",
              "object_hunt_crossley_dissipation": ">= 0",
              "compliant_body": one_of(COMPLIANT_BODIES),
              # One reflected inertia per arm joint (scene/franka.add_franka indexes them).
              "armature": f"vector {NUM_JOINTS} >= 0",
              # Drake's plant settings the scene relies on: a discrete plant (the policy clock
              # counts its steps; 0 would make it continuous), contact as Drake names it (a
              # misspelt name otherwise fails deep in AddMultibodyPlant, after config.yaml).
              "plant.time_step": "> 0", "plant.penetration_allowance": "> 0",
              "plant.stiction_tolerance": "> 0", "plant.sap_near_rigid_threshold": ">= 0",
              "plant.contact_model": one_of(CONTACT_MODELS),
              "plant.discrete_contact_approximation": one_of(DISCRETE_CONTACT_APPROXIMATIONS),
              "plant.contact_surface_representation": one_of(CONTACT_SURFACE_REPRESENTATIONS)}
    # The policy acts every policy_period: the plant must step there exactly (timing.PolicyClock).
    RELATIONS = (relation("policy_period", "a whole number (>= 1) of {plant.time_step} steps",
                          whole_multiple, "plant.time_step"),)
    # Drake's own plant settings (time step, contact model and approximation, ...), passed as
    # they are to AddMultibodyPlant (scene/builder.py). In YAML: physics: {plant: {...}}.
    plant: MultibodyPlantConfig = dc.field(default_factory=_plant_config)
    policy_period: float = 0.1
    # Used when the object is the compliant side: 1e7 Pa blew up at 12.5 ms in probes, 1e6
    # kicked a resting box 2.5 mm on its first step, 1e5 rested within 0.3 mm.
    object_hydroelastic_modulus: float = 1.0e5
    # Which side of object-table contact is compliant: "object" (compliant hulls on a rigid
    # table) or "table" (rigid hulls on a compliant table). Thin hulls (plates, books) made
    # compliant blew up at 12.5 ms (21 of 24 drops of a 1.5 cm plate); with a 1e6 Pa table,
    # 3 of 24 failed and resting objects stay within 0.3 mm (1e5: 2.8 mm sink; 1e7: more
    # drop failures). The table being compliant keeps every object's contact a patch.
    compliant_body: str = "table"
    table_hydroelastic_modulus: float = 1.0e6
    table_resolution_hint: float = 0.02
    object_hunt_crossley_dissipation: float = 5.0
    # Reflected rotor inertia and damping from the authors' system identification.
    armature: list[float] = dc.field(
        default_factory=lambda: [0.192, 0.54, 0.128, 0.172, 0.15, 0.08, 0.06])
    gravity_on_robot: bool = False

    # The physics step is the plant's. This property (no field: the YAML loader and dumper see
    # only plant.time_step) keeps `physics.time_step` readable and settable for the policy
    # clock, the energy meter and the stable-pose drops.
    @property
    def time_step(self) -> float:
        return self.plant.time_step

    @time_step.setter
    def time_step(self, value: float) -> None:
        self.plant.time_step = value


pickle_as_yaml(MultibodyPlantConfig)


OBJECT_KINDS = ("box", "cylinder", "library")


LIBRARY_OBJECTS = ("one", "train")


@dc.dataclass
class ObjectConfig:
    # Range checks (config/plumbing/bounds.py): what check_bounds refuses.
    # Sizes have upper bounds (issue 63: an unbounded size ran out of memory after the config
    # was written): 65536 points a cloud, 128x the policy's 512.
    BOUNDS = {"radius": "> 0",
              "length": "> 0", "mass": "> 0", "cloud_points": "[1, 65536]",
              "kind": one_of(OBJECT_KINDS), "size": "vector 3 > 0",
              # Which library and object: check() below says which combinations name objects.
              "library": "text", "library_objects": one_of(LIBRARY_OBJECTS), "object_id": "text"}
    # "box" | "cylinder": a primitive built in code; "library": objects from a library folder.
    kind: str = "box"
    size: list[float] = dc.field(default_factory=lambda: [0.09, 0.07, 0.05])  # box x,y,z
    radius: float = 0.04  # cylinder radius
    length: float = 0.08  # cylinder length
    library: str = ""  # folder holding manifest.json (kind: library)
    # Which of the library's objects (kind: library): "one", the object `object_id`, for the
    # whole run; "train", every train object of the library, each env taking the next one
    # every episode in seeded rounds (rl/envs/vec_env.cycle_object), as `train --objects` sets.
    library_objects: str = "one"
    object_id: str = ""  # id in the library's manifest (library_objects: one)
    mass: float = 0.3
    cloud_points: int = 512

    def check(self) -> None:
        """InputError naming the field where kind, library, library_objects and object_id do
        not name objects; every reader calls it before it builds or lists anything."""
        if self.kind not in OBJECT_KINDS:
            raise InputError(f"scene.object.kind must be one of {', '.join(OBJECT_KINDS)}, "
                             f"got {self.kind!r}")
        if self.kind != "library":
            return
        if not self.library:
            raise InputError("scene.object.library is empty: kind library needs the library "
                             "folder")
        if self.library_objects not in LIBRARY_OBJECTS:
            raise InputError(f"scene.object.library_objects must be one of "
                             f"{', '.join(LIBRARY_OBJECTS)}, got {self.library_objects!r}")
        if self.library_objects == "one" and not self.object_id:
            raise InputError(f"scene.object.object_id is empty: name one object of library "
                             f"{self.library}, or set library_objects: train for all its train "
                             "objects")
        if self.library_objects == "train" and self.object_id:
            raise InputError(f"scene.object.object_id {self.object_id!r} with library_objects: "
                             "train (every train object): give one or the other")

    @property
    def cycles_library(self) -> bool:
        """True when the envs go through every train object of `library` (checked first)."""
        self.check()
        return self.kind == "library" and self.library_objects == "train"


@dc.dataclass
class RandomizationConfig:
    # Range checks (config/plumbing/bounds.py): what check_bounds refuses.
    BOUNDS = {"mass": "range > 0",
              "object_friction": "range >= 0", "table_friction": "range >= 0",
              "finger_friction": "range >= 0", "restitution": "range [0, 1]",
              "torque_noise_std": ">= 0", "object_radius": "optional range > 0"}
    enabled: bool = True
    mass: list[float] = dc.field(default_factory=lambda: [0.1, 0.5])
    # Rescale each episode's object to a radius (m) drawn from [low, high]; absent (null), the
    # object keeps its own size (library objects are sized when the library is built).
    object_radius: typing.Optional[list[float]] = None
    object_friction: list[float] = dc.field(default_factory=lambda: [0.7, 1.0])
    table_friction: list[float] = dc.field(default_factory=lambda: [0.3, 0.8])
    finger_friction: list[float] = dc.field(default_factory=lambda: [1.0, 1.5])
    # Drake's SAP contact is inelastic: restitution is sampled and reported to the policy as in
    # the paper but has no physical effect here.
    restitution: list[float] = dc.field(default_factory=lambda: [0.0, 0.2])
    # Std of N(0, s) joint-torque noise (N m) per physics step. The authors add it only for the
    # student / phase-2 fine-tuning, so the teacher diagram sets 0.
    torque_noise_std: float = 0.0

    def check(self) -> None:
        """InputError naming a randomization range no draw can come from."""
        r = self.object_radius
        if r is not None and not (len(r) == 2 and 0 < r[0] <= r[1]):
            raise InputError(f"randomization.object_radius must be [low, high] with 0 < low <= "
                             f"high (m), or null to keep the object's size; got {r}")


@dc.dataclass
class ControllerConfig:
    # Range checks (config/plumbing/bounds.py): what check_bounds refuses.
    BOUNDS = {
              "max_position_delta": "> 0", "max_rotation_delta": "> 0", "kp_range": "range > 0",
              "rho_range": "range >= 0", "ik_damping": ">= 0", "ee_clamp": "> 0",
              "object_margin": ">= 0",
              # Per arm joint; 0 would train a robot that cannot move.
              "effort_limits": f"vector {NUM_JOINTS} > 0",
              "torque_backend": one_of(TORQUE_BACKENDS)}
    max_position_delta: float = 0.06  # m, residual EE translation at |a| = 1
    max_rotation_delta: float = 0.1  # rad, residual axis-angle at |a| = 1
    kp_range: list[float] = dc.field(default_factory=lambda: [10.0, 200.0])
    rho_range: list[float] = dc.field(default_factory=lambda: [0.1, 2.0])
    ik_damping: float = 0.01  # dq = J^T (J J^T + ik_damping I)^-1 e
    ee_clamp: float = 0.1  # target within +- this of the current EE position
    object_margin: float = 0.2  # target within object position +- (radius + margin)
    effort_limits: list[float] = dc.field(
        default_factory=lambda: [87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])
    # "symbolic": the torque law compiled into a C++ SymbolicVectorSystem (fast);
    # "python": the same law in a Python LeafSystem (see systems/control/impedance_controller.py).
    torque_backend: str = "symbolic"


@dc.dataclass
class SceneConfig:
    # Range checks (config/plumbing/bounds.py): the table box's extent (m) and the arm base's position.
    BOUNDS = {"table_size": "vector 3 > 0", "robot_base": "vector 3 finite"}
    physics: PhysicsConfig = dc.field(default_factory=PhysicsConfig)
    object: ObjectConfig = dc.field(default_factory=ObjectConfig)
    table_size: list[float] = dc.field(default_factory=lambda: [0.4, 0.5, 0.4])
    robot_base: list[float] = dc.field(default_factory=lambda: [-0.5, 0.0, 0.4])
