"""Why an episode failed: one category per evaluated episode, from its status and the object's
motion, so a report says where a policy falls short and not only how often.

Rules, first match wins (the task's tolerances: success_position, success_orientation):

  success               the task's success held at the end
  sim_error             the simulation failed (the step raised; the episode was cut)
  out_of_workspace      the object left the workspace (the task's own termination)
  never_touched         the object ended within 1 cm and 0.05 rad of where it started: the hand
                        never moved it (or only nudged it)
  tipped_or_rolled      the object ended on another face than the goal's: its body-frame
                        "up" direction is more than 0.5 rad from the goal's (the paper's push
                        tasks keep the face; full6d asks for one)
  near_miss             within twice the tolerances (position, and orientation when the task
                        checks it): close, but not close enough
  moved_away_from_goal  the object ended farther from the goal (xy) than it started
  short_of_goal         moved toward the goal but stopped outside twice the tolerance

A success is the task's (the paper's rule: within tolerance at any policy period, no stillness
check), so it can be a pose the object passes through mid-push. Each row also keeps the object's
speed at the end (`end_speed`) and a report counts the successes that ended with the object
still (`successes_ending_still`: under 2 cm/s and 0.2 rad/s).
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from corn_drake.config.primitive import at_rest
from corn_drake.transforms import quat_wxyz_to_matrix, rotation_angle, up_angle

# An object whose body-frame up direction is more than this from the goal's rests on another
# face (0.5 rad ~ 29 deg: beyond the few degrees a push tilts an object that stays on its face).
TIPPED_ANGLE_RAD = 0.5

FAILURES = ("success", "sim_error", "out_of_workspace", "never_touched", "tipped_or_rolled",
            "near_miss", "moved_away_from_goal", "short_of_goal")
UNTOUCHED_DISTANCE_M = 0.01
UNTOUCHED_ANGLE_RAD = 0.05
NEAR_MISS_FACTOR = 2.0


def _rotation(pose7: np.ndarray) -> np.ndarray:
    return quat_wxyz_to_matrix(np.asarray(pose7, float)[3:7])


def motion_summary(start: np.ndarray, end: np.ndarray, goal: np.ndarray) -> dict:
    """The object's motion over an episode, from its start, end and goal poses ([p, q_wxyz]):
    how far it moved and turned, its xy distance to the goal at the start and the end, and the
    angle between its body-frame up directions at the end and at the goal."""
    start, end, goal = (np.asarray(x, float) for x in (start, end, goal))
    R0, R1, Rg = _rotation(start), _rotation(end), _rotation(goal)
    return {"moved": float(np.linalg.norm(end[:3] - start[:3])),
            "turned": rotation_angle(R0.T @ R1),
            "start_position_error": float(np.linalg.norm(goal[:2] - start[:2])),
            "end_position_error": float(np.linalg.norm(goal[:2] - end[:2])),
            "up_error": up_angle(R1, Rg)}


def failure_category(row: dict, task) -> str:
    """The category of one evaluated episode: `row` has success, sim_error, out_of_workspace,
    position_error, orientation_error and motion (motion_summary); `task` a TaskConfig."""
    if row.get("success"):
        return "success"
    if row.get("sim_error"):
        return "sim_error"
    if row.get("out_of_workspace"):
        return "out_of_workspace"
    motion = row["motion"]
    if motion["moved"] < UNTOUCHED_DISTANCE_M and motion["turned"] < UNTOUCHED_ANGLE_RAD:
        return "never_touched"
    if motion["up_error"] > TIPPED_ANGLE_RAD:
        return "tipped_or_rolled"
    position = row.get("position_error")
    position = motion["end_position_error"] if position is None else position
    near = position <= NEAR_MISS_FACTOR * task.success_position
    if task.check_orientation:
        orientation = row.get("orientation_error")
        near = near and orientation is not None and \
            orientation <= NEAR_MISS_FACTOR * task.success_orientation
    if near:
        return "near_miss"
    if motion["end_position_error"] > motion["start_position_error"]:
        return "moved_away_from_goal"
    return "short_of_goal"


def successes_ending_still(rows: list[dict]) -> int:
    """How many successful report rows ended with the object still (rows with end_speed)."""
    return sum(1 for row in rows if row.get("success") and row.get("end_speed") is not None
               and at_rest(row["end_speed"]))


def failure_counts(rows: list[dict]) -> dict[str, int]:
    """{category: episodes} over report rows, every category listed (0 where none)."""
    counts = Counter(row["failure"] for row in rows)
    return {name: int(counts.get(name, 0)) for name in FAILURES}
