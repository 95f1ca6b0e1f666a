"""Loading our own Panda model (models/franka_panda/panda.urdf) into a MultibodyPlant, offline."""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex

from corn_drake.contract import NUM_JOINTS
from corn_drake.scene.gripper import PANDA_URDF, TOOL_FRAME

JOINT_NAMES = tuple(f"panda_joint{i}" for i in range(1, NUM_JOINTS + 1))
EFFORT_LIMITS = np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])
JOINT_LOWER = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
JOINT_UPPER = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
FINGER_BODIES = ("panda_leftfinger", "panda_rightfinger")


def add_franka(plant: MultibodyPlant, X_WBase: RigidTransform,
               armature: list[float] | None = None) -> ModelInstanceIndex:
    """Parses the Panda, welds panda_link0 at X_WBase and sets the reflected rotor inertia.

    The URDF carries no package:// URIs, so the parser needs no package map and no network.
    """
    parser = Parser(plant)
    (panda,) = parser.AddModels(str(PANDA_URDF))
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("panda_link0", panda), X_WBase)
    if armature is not None:
        if len(armature) != NUM_JOINTS:
            raise ValueError(f"armature needs {NUM_JOINTS} values, got {len(armature)}")
        # Reflected inertia = rotor_inertia * gear_ratio^2; with ratio 1 the rotor inertia is the
        # identified armature. It is what keeps the explicit joint PD stable at 80 Hz.
        for i, value in enumerate(armature):
            actuator = plant.GetJointActuatorByName(f"panda_motor{i + 1}", panda)
            actuator.set_default_rotor_inertia(float(value))
            actuator.set_default_gear_ratio(1.0)
    return panda


def make_controller_plant(armature: list[float] | None = None) -> MultibodyPlant:
    """A robot-only, finalized continuous plant for kinematics (Jacobians) inside controllers."""
    plant = MultibodyPlant(0.0)
    add_franka(plant, RigidTransform(), armature)
    plant.Finalize()
    return plant


def tool_frame(plant: MultibodyPlant, panda: ModelInstanceIndex | None = None):
    if panda is None:
        return plant.GetFrameByName(TOOL_FRAME)
    return plant.GetFrameByName(TOOL_FRAME, panda)
