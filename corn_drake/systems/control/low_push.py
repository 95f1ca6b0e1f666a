"""Where a side push aims: the chosen contact point, or the same side of the object lowered
toward the table (PrimitiveConfig.push_height).

Why: a horizontal push at height h on an object standing on a base of half-width b (along the
push) tips it rather than slides it once mu * h > b, mu being the table's friction (0.3-0.8
here). The encoder's patch centres on an upright bottle or a tall box sit at mid-height, 5-10 cm
up; most failed push_turn episodes ended tipped or rolled (the primitive results log). Lowering
the fingers alone does not lower the push on a tall object: the palm, deeper than the fingers,
meets it first, 4.5 cm and more above the tool point (an upright 5 x 5 x 10 cm box tipped
either way). With the fingers leaning toward the surface as well (finger_tilt_deg,
systems/primitive_executor.facing_rotation) the same push slid it upright.

The lowering keeps the contact's horizontal position and only moves the pre-contact point down,
and only as far as the object's cloud leaves room: the fingers descend through a vertical
column (FINGER_COLUMN_RADIUS) around the pre-contact point, and must stay above every cloud
point in it (an object wider at its base, a frustum or a lying bottle's bulge, stops them
higher). Sloped and top faces (a normal whose horizontal part is under HORIZONTAL_MIN of its
length) keep their own point: lowering their pre-contact point would put it inside the object.

The returned point is where the executor's pre-contact point (point + pre_contact_distance *
normal) lands at the lowered height, so the executor, its displays and the primitive contract
are unchanged: the primitive's `point` is the point the push aims at.
"""

from __future__ import annotations

import numpy as np

from corn_drake.config.primitive import PrimitiveConfig
from corn_drake.scene.objects import TABLE_TOP_Z

# The closed fingers are 0.021 x 0.04 m around the tool point: a column of this radius around
# the pre-contact point holds them with ~1 cm to spare.
FINGER_COLUMN_RADIUS = 0.03
# The fingertips are 9 mm below the tool point; the tool stays this far above the highest cloud
# point in the column (tips ~6 mm above it).
FINGER_DEPTH = 0.015
# Only normals at least this horizontal (|n_xy| / |n|) are lowered: side faces.
HORIZONTAL_MIN = 0.7


def push_contact(cloud: np.ndarray, normals: np.ndarray, index: int,
                 cfg: PrimitiveConfig) -> tuple[np.ndarray, np.ndarray]:
    """(point, normal) the primitive aims at for the policy's choice of cloud point `index`:
    the point itself, or (cfg.push_height > 0, a side face) lowered toward push_height above
    the table as far as the cloud leaves room for the fingers."""
    point = np.asarray(cloud[index], float).copy()
    normal = np.asarray(normals[index], float)
    norm = np.linalg.norm(normal)
    if cfg.push_height <= 0 or norm < 1e-9 or \
            np.linalg.norm(normal[:2]) < HORIZONTAL_MIN * norm:
        return point, normal
    pre = point + cfg.pre_contact_distance * normal / norm
    target = TABLE_TOP_Z + max(cfg.push_height, cfg.min_tool_height)
    if pre[2] <= target:
        return point, normal
    xy = np.asarray(cloud, float)
    near = np.linalg.norm(xy[:, :2] - pre[:2], axis=1) < FINGER_COLUMN_RADIUS
    floor = xy[near, 2].max() + FINGER_DEPTH if near.any() else -np.inf
    lowered = min(pre[2], max(target, floor))
    point[2] += lowered - pre[2]
    return point, normal
