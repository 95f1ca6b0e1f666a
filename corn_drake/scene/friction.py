"""Per-geometry friction coefficients that give the paper's combined friction in Drake.

The paper's simulator (PhysX, average combine mode) gives a contact between surfaces with
coefficients a and b the friction (a + b) / 2; Drake gives 2ab / (a + b), which is lower whenever
a != b (object 0.7 on table 0.3: 0.42 instead of 0.50). The sampled (paper) values stay what the
policy observes; only the coefficients written into the geometries change, so that the two
contacts that decide a push come out as the paper intends:

    object-table:  2 o t / (o + t) = (O + T) / 2 =: A
    object-finger: 2 o f / (o + f) = (O + F) / 2 =: B

Two equations, three unknowns. Solving for the table and finger, t = A o / (2o - A) and
f = B o / (2o - B), which are positive only when o > A/2 and o > B/2. The free choice o = max(A, B)
satisfies both for any positive inputs and keeps every coefficient within (min(A, B)/2, max(A, B)]:
the pair with the larger target gets o on both sides, the other side of the other pair lies
between half its target and its target. Pairs that do not involve the object (finger-table, arm
links) are not matched; the object never sees them.
"""

from __future__ import annotations

import dataclasses
import math

from corn_drake.errors import InputError


@dataclasses.dataclass(frozen=True)
class GeometryFriction:
    """Coefficients to write into the object's, the table's and the fingers' geometries."""
    object: float
    table: float
    finger: float


def _partner(target: float, own: float) -> float:
    """The coefficient x with drake_combined(own, x) == target (needs own > target / 2)."""
    return target * own / (2.0 * own - target)


def geometry_friction(object_mu: float, table_mu: float, finger_mu: float) -> GeometryFriction:
    """Per-geometry coefficients whose Drake combinations equal the paper's averages."""
    for name, mu in (("object_friction", object_mu), ("table_friction", table_mu),
                     ("finger_friction", finger_mu)):
        if not (math.isfinite(mu) and mu > 0):
            raise InputError(f"{name} must be a positive finite friction coefficient, got {mu!r}")
    object_table = (object_mu + table_mu) / 2
    object_finger = (object_mu + finger_mu) / 2
    o = max(object_table, object_finger)
    return GeometryFriction(object=o, table=_partner(object_table, o),
                            finger=_partner(object_finger, o))
