"""The failure categories of evaluate's reports (evaluation/failures.py), on hand-made episodes."""

import math

import numpy as np
import pytest

from corn_drake.config.primitive import at_rest
from corn_drake.config.task import TaskConfig
from corn_drake.evaluation.failures import (FAILURES, failure_category, failure_counts,
                                            motion_summary, successes_ending_still)

UPRIGHT = [1.0, 0.0, 0.0, 0.0]
# 90 degrees about x: the object lies on its side.
ON_SIDE = [math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0]
YAW_30 = [math.cos(math.pi / 12), 0.0, 0.0, math.sin(math.pi / 12)]


def _row(start, end, goal, **status):
    row = {"success": False, "sim_error": None, "out_of_workspace": False,
           "motion": motion_summary(start, end, goal)}
    row["position_error"] = row["motion"]["end_position_error"]
    row["orientation_error"] = status.pop("orientation_error", 0.0)
    return {**row, **status}


PUSH = TaskConfig(name="push", check_orientation=False)   # 5 cm, position only
FULL6D = TaskConfig()                                       # 5 cm and 0.1 rad
GOAL = [0.10, 0.0, 0.45, *UPRIGHT]


@pytest.mark.parametrize("row, task, expected", [
    (_row([0, 0, 0.45, *UPRIGHT], [0.1, 0, 0.45, *UPRIGHT], GOAL, success=True), PUSH, "success"),
    (_row([0, 0, 0.45, *UPRIGHT], [0, 0, 0.45, *UPRIGHT], GOAL, sim_error="NaN"), PUSH,
     "sim_error"),
    (_row([0, 0, 0.45, *UPRIGHT], [0.6, 0, 0.45, *UPRIGHT], GOAL, out_of_workspace=True), PUSH,
     "out_of_workspace"),
    # Moved 5 mm and turned 0.01 rad: a nudge, not a push.
    (_row([0, 0, 0.45, *UPRIGHT], [0.005, 0, 0.45, *UPRIGHT], GOAL), PUSH, "never_touched"),
    # Knocked over on its way to the goal.
    (_row([0, 0, 0.45, *UPRIGHT], [0.09, 0, 0.43, *ON_SIDE], GOAL), PUSH, "tipped_or_rolled"),
    # 8 cm short of a 10 cm push: within twice the 5 cm tolerance.
    (_row([0, 0, 0.45, *UPRIGHT], [0.03, 0, 0.45, *UPRIGHT], GOAL), PUSH, "near_miss"),
    # Pushed the wrong way.
    (_row([0, 0, 0.45, *UPRIGHT], [-0.05, 0, 0.45, *UPRIGHT], GOAL), PUSH, "moved_away_from_goal"),
    # Toward the goal, but it was 30 cm away and the push stopped 20 cm short.
    (_row([-0.2, 0, 0.45, *UPRIGHT], [-0.1, 0, 0.45, *UPRIGHT], GOAL), PUSH, "short_of_goal"),
    # On the paper's task the position is right but the yaw is 0.52 rad off: not a near miss.
    (_row([0, 0, 0.45, *UPRIGHT], [0.1, 0, 0.45, *YAW_30], GOAL, orientation_error=0.52), FULL6D,
     "short_of_goal"),
    (_row([0, 0, 0.45, *UPRIGHT], [0.1, 0, 0.45, *YAW_30], GOAL, orientation_error=0.15), FULL6D,
     "near_miss"),
])
def test_each_rule_on_a_hand_made_episode(row, task, expected):
    assert failure_category(row, task) == expected


def test_motion_summary_measures_what_it_names():
    m = motion_summary([0, 0, 0.45, *UPRIGHT], [0.03, 0.04, 0.45, *YAW_30], GOAL)
    assert m["moved"] == pytest.approx(0.05)
    assert m["turned"] == pytest.approx(math.pi / 6)
    assert m["start_position_error"] == pytest.approx(0.10)
    assert m["end_position_error"] == pytest.approx(np.hypot(0.07, 0.04))
    assert m["up_error"] == pytest.approx(0.0, abs=1e-9)  # a yaw keeps the face
    assert motion_summary(GOAL, [0, 0, 0.4, *ON_SIDE], GOAL)["up_error"] == \
        pytest.approx(math.pi / 2)


def test_counts_list_every_category():
    counts = failure_counts([{"failure": "success"}, {"failure": "near_miss"},
                             {"failure": "near_miss"}])
    assert list(counts) == list(FAILURES)
    assert counts["near_miss"] == 2 and counts["success"] == 1 and sum(counts.values()) == 3


def test_successes_ending_still_count_only_successes_at_rest():
    assert at_rest({"linear": 0.019, "angular": 0.19})
    assert not at_rest({"linear": 0.021, "angular": 0.0})
    assert not at_rest({"linear": 0.0, "angular": 4.2})  # spinning through the goal
    assert at_rest({"linear": 0.03, "angular": 0.3}, linear=0.05, angular=0.5)  # a config's speeds
    rows = [{"success": True, "end_speed": {"linear": 0.001, "angular": 0.01}},
            {"success": True, "end_speed": {"linear": 0.3, "angular": 4.0}},
            {"success": False, "end_speed": {"linear": 0.0, "angular": 0.0}},
            {"success": True}]  # a report row from before end_speed was kept
    assert successes_ending_still(rows) == 1
