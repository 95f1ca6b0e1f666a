"""Pushes shortened so the object stays on the table (PrimitiveConfig.keep_on_table).

Out of 200 unseen push_turn episodes the primitive policies left 29-54 objects off the table
(the 0.4 x 0.5 m table; the goal region ends 4-5 cm from its edges), and a penalty for it only
taught the policy to push less (docs/results/primitive/, item 22). Here the executor itself
refuses the part of a push that would carry the object's centre past the table's edge: the
policy keeps choosing where to touch and which way to push, and a push toward the edge ends
early. Plain arithmetic, so the planner's tests can drive it directly.
"""

from __future__ import annotations

import numpy as np


def push_kept_on_table(push, object_xy, table_half_xy, margin: float,
                       gap: float) -> np.ndarray:
    """`push` (3,: the tool's travel from the pre-contact point, world frame) shortened along
    its own horizontal direction so that the object, carried as far as the push goes beyond
    its first `gap` metres (the air between the pre-contact point and the surface), keeps its
    centre `object_xy` at least `margin` inside the table (centred at the origin, half extents
    `table_half_xy`). Unchanged when it already does; at least `gap` long (the tool still
    reaches the surface) when the object's centre is already past the limit. The vertical part
    is kept."""
    push = np.array(push, float)
    length = float(np.linalg.norm(push[:2]))
    travel = length - gap
    if length < 1e-9 or travel <= 0.0:
        return push
    u = push[:2] / length
    limit = np.asarray(table_half_xy, float) - margin
    c = np.asarray(object_xy, float)
    allowed = travel
    for axis in range(2):
        if u[axis] > 1e-9:
            allowed = min(allowed, max((limit[axis] - c[axis]) / u[axis], 0.0))
        elif u[axis] < -1e-9:
            allowed = min(allowed, max((-limit[axis] - c[axis]) / u[axis], 0.0))
    if allowed >= travel:
        return push
    push[:2] *= (gap + allowed) / length
    return push
