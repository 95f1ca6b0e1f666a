"""The goal variants of a task, selected in YAML by a tag on `task.goal`:

    task:
      name: planar
      goal: !PlanarGoal {distance: [0.1, 0.15], max_yaw: 0.5}

Each variant holds only its own ranges; an untagged `goal:` mapping is the first variant
(Full6dGoal, the paper's task). corn_drake/tasks/sampling.py draws an episode's object start
and goal for each. No imports from corn_drake.config (it imports this module), and no
`from __future__ import annotations`: yaml_load_typed needs real types on the fields.
"""

import dataclasses as dc
import math
import typing


@dc.dataclass
class Full6dGoal:
    """The paper's 6D task: the goal is any stable pose of the object (thin objects keep the one
    they start in: pushing cannot stand them up), any yaw, anywhere in the goal region."""
    # The object starts at least this far (xy, m) from the tool (official code).
    object_min_distance_to_hand: float = 0.12
    # Goal at least this far (xy, m) from the start. The paper says 0.1 m; the authors' code
    # samples with 0.05 * 1.1 = 0.055 m, which we keep (the behaviour the results came from).
    min_goal_distance: float = 0.055


@dc.dataclass
class PlanarGoal:
    """A planar goal: the object keeps the stable pose it starts in and is moved `distance` (m,
    in a uniformly random direction) and turned by up to +- `max_yaw` (rad)."""
    object_min_distance_to_hand: float = 0.12
    distance: list[float] = dc.field(default_factory=lambda: [0.1, 0.2])
    max_yaw: float = math.pi


@dc.dataclass
class PushFromHandGoal:
    """A push from where the hand starts: the object rests `object_distance_to_hand` (xy, m)
    from the tool, and the goal lies `distance` (m) beyond it, within +- `heading_spread` (rad)
    of the hand-to-object direction, so one straight push reaches it; same stable pose, turned
    by up to +- `max_yaw`. The defaults are the push benchmark's (diagrams/tasks/push.yaml):
    the shortest push that still needs the hand to find the object, the goal keeping the yaw."""
    object_distance_to_hand: list[float] = dc.field(default_factory=lambda: [0.08, 0.11])
    distance: list[float] = dc.field(default_factory=lambda: [0.08, 0.12])
    heading_spread: float = 0.5
    max_yaw: float = 0.0


# The first variant is what an untagged `goal:` mapping loads as (and how yaml_dump_typed
# writes it back: untagged).
GoalSpec = typing.Union[Full6dGoal, PlanarGoal, PushFromHandGoal]
