"""Reference controllers with the learned policies' interface (`act(obs)`): the scripted
pusher and the zero action.

ScriptedPushAgent exercises the controller without a learned policy (the demo, notebook 01,
tests/test_scene_physics.py) and is `corn-drake evaluate --run scripted`: go to a point
behind the object on its goal line, descend, then push through the goal, with fixed gains and
the gripper pointing down.
"""

from __future__ import annotations

import numpy as np

from corn_drake.config.scene import ControllerConfig
from corn_drake.contract import ACTION_DIM, ACTION_SLICES, NUM_KEYPOINTS
from corn_drake.scene.objects import TABLE_TOP_Z
from corn_drake.transforms import from_pose9

# Tool frame pointing down (tool z = world -z), fingers spanning world y.
R_DOWN = np.diag([1.0, -1.0, -1.0])


def _log_so3(R: np.ndarray) -> np.ndarray:
    angle = np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))
    if angle < 1e-9:
        return np.zeros(3)
    if np.pi - angle < 1e-6:  # axis from the symmetric part near pi
        axis = np.sqrt(np.maximum((np.diag(R) + 1) / 2, 0.0))
        i = int(np.argmax(axis))
        axis[np.arange(3) != i] = R[i, np.arange(3) != i] / (2 * axis[i])
        return angle * axis / np.linalg.norm(axis)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return angle * w / (2 * np.sin(angle))


def action_towards(tool_p: np.ndarray, tool_R: np.ndarray, target_p: np.ndarray,
                   cfg: ControllerConfig, kp: float = 120.0, rho: float = 1.0,
                   target_R: np.ndarray = R_DOWN) -> np.ndarray:
    """Normalised action moving the tool towards target_p / target_R with fixed gains."""
    action = np.empty(ACTION_DIM)
    action[ACTION_SLICES["position"]] = np.clip((target_p - tool_p) / cfg.max_position_delta, -1, 1)
    action[ACTION_SLICES["rotation"]] = np.clip(
        _log_so3(target_R @ tool_R.T) / cfg.max_rotation_delta, -1, 1)
    action[ACTION_SLICES["kp"]] = (kp - np.mean(cfg.kp_range)) / (np.ptp(cfg.kp_range) / 2)
    action[ACTION_SLICES["rho"]] = (rho - np.mean(cfg.rho_range)) / (np.ptp(cfg.rho_range) / 2)
    return action


class ScriptedPushAgent:
    """A stateless straight-line pusher with the learned policies' interface (`act(obs)`).

    From the observation alone: the object's centre and footprint from its bounding-box
    keypoints, the goal from the relative goal. Go to a point behind the object on the
    goal line (above the object while passing over it), descend, then push the tool through
    the goal's position. A reference for the push benchmark (`corn-drake evaluate --run
    scripted`), not a learned policy: it knows nothing about how objects turn or roll.
    """

    def __init__(self, cfg: ControllerConfig, push_height: float = 0.02, clearance: float = 0.03,
                 lateral_tolerance: float = 0.03):
        self.cfg = cfg
        self.push_height, self.clearance = push_height, clearance
        self.lateral_tolerance = lateral_tolerance

    def act(self, obs: dict) -> np.ndarray:
        corners = np.asarray(obs["object_keypoints"], float).reshape(NUM_KEYPOINTS, 3)
        c = corners[:, :2].mean(axis=0)
        radius = float(np.max(np.linalg.norm(corners[:, :2] - c, axis=1)))
        to_goal = np.asarray(obs["goal"], float)[:2]
        u = to_goal / max(np.linalg.norm(to_goal), 1e-6)
        p, R = from_pose9(obs["hand_state"])
        z_push = TABLE_TOP_Z + self.push_height
        z_over = corners[:, 2].max() + self.clearance
        rel = p[:2] - c
        along, lateral = rel @ u, np.linalg.norm(rel - (rel @ u) * u)
        behind = c - (radius + self.clearance) * u
        if along <= -radius and lateral <= self.lateral_tolerance:
            # Lined up behind the object: down to push height, then through the goal.
            low = p[2] < z_push + 0.01
            target = np.array([*(c + to_goal), z_push]) if low else np.array([*p[:2], z_push])
        else:
            # Not lined up: travel to the pre-push point, over the object if the path crosses it.
            near = np.linalg.norm(rel) < radius + self.clearance
            away = np.linalg.norm(p[:2] - behind) > self.lateral_tolerance
            z = z_over if near or away else z_push
            target = np.array([*behind, max(z, z_push)])
        return action_towards(p, R, target, self.cfg)


class HoldStillAgent:
    """The zero action (no residual, mid-range gains): the floor a learned policy must beat —
    objects that roll or settle into the goal by themselves count as its successes."""

    def __init__(self, cfg: ControllerConfig | None = None):
        self.cfg = cfg

    def act(self, obs: dict) -> np.ndarray:
        return np.zeros(ACTION_DIM)
