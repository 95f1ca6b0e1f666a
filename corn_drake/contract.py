"""The policy's observation/action contract and the state layouts every layer shares.

One home for the sizes that the Drake systems (systems/), the gymnasium env and trainer (rl/)
and the networks (nn/) must agree on. Every other module imports these names instead of
writing a number: tests/test_contract.py fails on a hard-coded observation or action size
outside this file.

Observation (teacher, privileged), one entry per key:
  cloud            (N, 3)  the object's surface sample at its current pose, world frame
  hand_state       (9,)    tool position + 6D rotation (first two columns of R), world frame
  robot_state      (14,)   joint positions then velocities
  previous_action  (20,)   the last action in physical units (see ACTION_SLICES)
  goal             (9,)    goal position minus object position + 6D of R_goal R_obj^T
  physics          (5,)    mass, table / object / finger friction, restitution
  object_keypoints (24,)   the 8 bounding-box corners at the current pose, world frame
The student sees cloud (partial, from the cameras), hand_state, robot_state, previous_action
and goal (relative to the tracker's estimate), with the teacher's shapes
(student_observation_shapes).

Encoder input normalisation: points and the hand position enter the encoders as
(x - ENCODER_INPUT_CENTER) / ENCODER_INPUT_SCALE. nn/encoders/input_normalization.py turns these numbers
into the module every encoder carries; encoder.pt saves the values it was pretrained with.

Action (normalised to [-1, 1]): EE translation residual (3, world), axis-angle residual
(3, world), joint stiffness kp (7), damping ratio rho (7).

Free-body state (Drake's MultibodyPlant state output of a model instance holding one free
body): [quaternion wxyz (4), position (3), angular velocity (3), linear velocity (3)].
"""

from __future__ import annotations

import numpy as np

NUM_JOINTS = 7  # Franka Panda arm joints (the fingers are welded closed)
# Height (m) of the table's top in the world frame, whatever its size (scene/builder.py puts the
# table box under it); here so the config's workspace check (config/teacher.py) can read it.
TABLE_TOP_Z = 0.4
ROBOT_STATE_DIM = 2 * NUM_JOINTS
POSE9_DIM = 9  # position + 6D rotation
POSE7_DIM = 7  # position + quaternion wxyz (Drake's pose order in our sources: p then q)
HAND_STATE_DIM = POSE9_DIM
GOAL_DIM = POSE9_DIM
POSITION_DIM = 3
# Inside a pose9 (hand_state, goal): the position, then the 6D rotation.
POSE9_POSITION = slice(0, POSITION_DIM)
POSE9_ROTATION = slice(POSITION_DIM, POSE9_DIM)
PHYSICS_DIM = 5
NUM_KEYPOINTS = 8  # bounding-box corners
KEYPOINTS_DIM = 3 * NUM_KEYPOINTS

# --- action ---------------------------------------------------------------------------------
ACTION_SLICES = {
    "position": slice(0, 3),
    "rotation": slice(3, 6),
    "kp": slice(6, 6 + NUM_JOINTS),
    "rho": slice(6 + NUM_JOINTS, 6 + 2 * NUM_JOINTS),
}
ACTION_DIM = 6 + 2 * NUM_JOINTS

# --- free-body state ------------------------------------------------------------------------
FREE_BODY_STATE_DIM = 13
FREE_BODY_QUATERNION = slice(0, 4)
FREE_BODY_POSITION = slice(4, 7)
FREE_BODY_ANGULAR_VELOCITY = slice(7, 10)
FREE_BODY_LINEAR_VELOCITY = slice(10, 13)
# A pose7 (POSE7_DIM: our pose sources, the tracker's estimate): position, then quaternion wxyz.
POSE7_POSITION = slice(0, 3)
POSE7_QUATERNION = slice(3, 7)

# --- observation ----------------------------------------------------------------------------
OBS_KEYS = ("cloud", "hand_state", "robot_state", "previous_action", "goal", "physics",
            "object_keypoints")
STUDENT_OBS_KEYS = ("cloud", "hand_state", "robot_state", "previous_action", "goal")
# The policy's context vector (normalised by running mean/std): these keys, concatenated.
CONTEXT_KEYS = ("goal", "previous_action", "robot_state", "physics")
DEFAULT_NUM_POINTS = 512


def observation_shapes(num_points: int = DEFAULT_NUM_POINTS) -> dict[str, tuple[int, ...]]:
    """Shape of each teacher observation key for a cloud of `num_points` points."""
    return {"cloud": (num_points, 3), "hand_state": (HAND_STATE_DIM,),
            "robot_state": (ROBOT_STATE_DIM,), "previous_action": (ACTION_DIM,),
            "goal": (GOAL_DIM,), "physics": (PHYSICS_DIM,), "object_keypoints": (KEYPOINTS_DIM,)}


def observation_size(key: str, num_points: int = DEFAULT_NUM_POINTS) -> int:
    return int(np.prod(observation_shapes(num_points)[key]))


def student_observation_shapes(num_points: int = DEFAULT_NUM_POINTS) -> dict[str, tuple[int, ...]]:
    """Shape of each student observation key: the teacher's shape of the same key."""
    shapes = observation_shapes(num_points)
    return {k: shapes[k] for k in STUDENT_OBS_KEYS}


def slice_size(s: slice) -> int:
    """Number of entries of a layout slice (one with explicit start and stop)."""
    return s.stop - s.start


CONTEXT_DIM = sum(observation_size(k) for k in CONTEXT_KEYS)
# The `state` baseline's object features: bounding-box keypoints + hand pose.
STATE_FEATURE_DIM = KEYPOINTS_DIM + HAND_STATE_DIM

# --- encoder input normalisation ------------------------------------------------------------
# The only normalisation any encoder of this project has been pretrained with: centre above the
# table (top at z = 0.4) and scale 0.4 m, so the workspace maps to about [-1, 1]. encoder.pt
# files saved before the normalisation was stored in them were all made with these values.
ENCODER_INPUT_CENTER = (0.0, 0.0, 0.55)
ENCODER_INPUT_SCALE = 0.4


def free_body_pose(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position, rotation matrix) of a free body from its state (FREE_BODY_STATE_DIM,)."""
    from corn_drake.transforms import quat_wxyz_to_matrix

    x = np.asarray(x)
    return x[FREE_BODY_POSITION], quat_wxyz_to_matrix(x[FREE_BODY_QUATERNION])


def check_action(action) -> np.ndarray:
    """A normalised action as a flat float array; a wrong size or a non-finite entry raises
    ValueError naming it (before anything reaches the simulator)."""
    action = np.asarray(action, dtype=float).reshape(-1)
    if action.shape != (ACTION_DIM,):
        raise ValueError(f"action must have {ACTION_DIM} values, got shape {action.shape}")
    if not np.isfinite(action).all():
        raise ValueError(f"action has non-finite entries at {np.flatnonzero(~np.isfinite(action)).tolist()}")
    return action

# Finished episodes behind a training history row's success rate, return and tracking error (the
# trainers' recent-episode window; the learning curves start where a run has filled it).
RECENT_EPISODES = 100


# --- the contact-primitive policy ------------------------------------------------------------
# A primitive (PrimitiveExecutor's `primitive` input): contact point (3, world), its outward
# normal (3), push motion (3, in [-1, 1], times PrimitiveConfig.push_distance), the chosen
# location's cloud index, the sequence number that starts it (executor count + 1).
PRIMITIVE_DIM = 11
PRIMITIVE_POINT, PRIMITIVE_NORMAL, PRIMITIVE_MOTION = slice(0, 3), slice(3, 6), slice(6, 9)
PRIMITIVE_LOCATION, PRIMITIVE_SEQUENCE = 9, 10
# The executor's `status` output: its phase, ticks in that phase, primitives started, whether
# the pre-contact pose was reached (1, 0, or -1 while pending), the current primitive's cloud
# index, its pre-contact point and the last commanded tool target.
PRIMITIVE_STATUS_LAYOUT = {"phase": 0, "ticks": 1, "count": 2, "reached": 3, "location": 4,
                           "pre_contact": slice(5, 8), "target": slice(8, 11),
                           "push": slice(11, 14)}
PRIMITIVE_STATUS_DIM = 14
# PrimitivePolicySystem's held `choice`: cloud index, location index, motion (3).
PRIMITIVE_CHOICE_DIM = 5
# Per-location features beside the token: position from the object's origin, goal flow,
# outward normal (3 each; nn/primitive_features.py).
PRIMITIVE_LOCAL_DIM = 9
