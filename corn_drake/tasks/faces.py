"""Which face an object rests on: the rule the failure table's `tipped_or_rolled` and the
primitive env's tipping penalty share, so "tipped" means one thing in training and evaluation."""

from __future__ import annotations

import numpy as np

from corn_drake.config.task import Full6dGoal, TaskConfig
from corn_drake.transforms import quat_wxyz_to_matrix, up_angle

# An object whose body-frame up direction is more than this from the goal's rests on another
# face (0.5 rad ~ 29 deg: beyond the few degrees a push tilts an object that stays on its face).
TIPPED_ANGLE_RAD = 0.5


def goal_keeps_face(task: TaskConfig) -> bool:
    """Whether the task's goals keep the face the object starts on (the push tasks): only the
    paper's 6D goal asks for another stable pose."""
    return not isinstance(task.goal, Full6dGoal)


def face_error(pose7: np.ndarray, goal7: np.ndarray) -> float:
    """Angle (rad) between the object's up direction (body frame) in two poses [p, q_wxyz]."""
    return up_angle(quat_wxyz_to_matrix(np.asarray(pose7, float)[3:7]),
                    quat_wxyz_to_matrix(np.asarray(goal7, float)[3:7]))
