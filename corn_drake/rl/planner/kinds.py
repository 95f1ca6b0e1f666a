"""The planner's primitive kinds: where to touch the object and which way to move, per kind,
from the object's privileged state (its cloud and normals in the world, its pose, the goal).

Every kind is one primitive of the same executor (systems/primitive_executor.py: up over the
object, down to the pre-contact point, a straight push, up again), so the hand only ever moves
through the controller; what a kind chooses is the contact and the motion:

  push    through the centre: a side point whose normal faces away from the goal, pushed
          toward the goal (lowered to push_height like every shipped push, systems/low_push.py:
          low, it slides the object instead of tipping it);
  turn    an offset push for yaw: a side point far from the centre whose inward push has the
          largest lever about the vertical through the centre, in the sense that closes the
          yaw error (lowered like a push);
  topple  a side point high above the centre, pushed horizontally across: the object tips
          about its far lower edge onto another face. Offered only when the goal's face is
          not the one down now (the body axis that must end up pointing up is more than
          TILTED_RAD from vertical); the push goes the way that brings that axis up. Aimed at
          the point's own height (`exact`: never lowered, a low push would slide it).

Ranked proposals per kind; the search (rl/planner/search.py) takes the first `per_kind` of each.
Plain numpy: the tests drive it on a box without a simulator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corn_drake.errors import InputError
from corn_drake.transforms import quat_wxyz_to_matrix

KINDS = ("push", "turn", "topple")
# Side faces: a normal at least this horizontal (|n_xy| / |n|), as low_push's HORIZONTAL_MIN.
SIDE = 0.7
# The goal's face counts as down when the axis that must point up is within this of vertical
# (failures.TIPPED_ANGLE_RAD's 0.5 rad: beyond what a push tilts an object on its face).
TILTED_RAD = 0.5
# The hand starts pre_contact_distance off the surface; the fingers are ~1 cm thick, so it
# travels this much before it touches: added to every push's length.
GAP = 0.03


@dataclass(frozen=True)
class Candidate:
    kind: str
    index: int  # the cloud point (the env's action names it)
    point: np.ndarray  # world (3,)
    normal: np.ndarray  # outward unit normal, world (3,)
    motion: np.ndarray  # (3,) in [-1, 1], times push_distance
    exact: bool  # aim at `point` itself (not lowered toward push_height)

    def describe(self) -> dict:
        return {"kind": self.kind, "index": self.index,
                "motion": [round(float(m), 4) for m in self.motion]}


def goal_errors(pose, goal) -> dict:
    """What is left to do, from the object's pose and the goal ([p, q_wxyz] each): `shift` (xy,
    m), `yaw` (rad, the goal's yaw about the vertical minus the current one, wrapped), `up_now`
    (the world direction, now, of the body axis that points up at the goal) and `tilt` (its
    angle from vertical: the face change left)."""
    pose, goal = np.asarray(pose, float), np.asarray(goal, float)
    R, Rg = quat_wxyz_to_matrix(pose[3:]), quat_wxyz_to_matrix(goal[3:])
    up_now = R @ (Rg.T @ np.array([0.0, 0.0, 1.0]))
    E = Rg @ R.T  # the turn left to do, in the world
    yaw = float(np.arctan2(E[1, 0] - E[0, 1], E[0, 0] + E[1, 1]))
    return {"shift": goal[:2] - pose[:2], "yaw": yaw, "up_now": up_now,
            "tilt": float(np.arccos(np.clip(up_now[2], -1.0, 1.0)))}


def _side(normals: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(normals, axis=1)
    return np.linalg.norm(normals[:, :2], axis=1) >= SIDE * np.maximum(n, 1e-9)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / max(np.linalg.norm(v), 1e-12)


def _motion(direction_xy, length: float, push_distance: float) -> np.ndarray:
    m = np.zeros(3)
    m[:2] = _unit(direction_xy) * length / push_distance
    # Scaled as a whole (not clipped per axis) so the direction is kept.
    return m / max(1.0, np.abs(m).max())


def _through_centre(cloud, normals, centre, u, usable, height=None) -> np.ndarray:
    """Usable side points facing against `u` (the push's direction), best first: the nearest
    to the line through the centre along u (a push through the centre translates), or with
    `height`, the highest with that offset as a penalty."""
    n_xy = normals[:, :2] / np.maximum(np.linalg.norm(normals[:, :2], axis=1), 1e-9)[:, None]
    facing = usable & (n_xy @ u[:2] < -0.5)
    r = cloud[:, :2] - centre[:2]
    lateral = np.abs(r[:, 0] * u[1] - r[:, 1] * u[0])
    cost = lateral if height is None else lateral - 0.5 * (cloud[:, 2] - centre[2])
    if height is not None:
        facing &= cloud[:, 2] >= height
    order = np.argsort(cost)
    return order[facing[order]]


def propose(cloud, normals, pose, goal, push_distance: float, reachable: np.ndarray,
            kinds=KINDS, per_kind: int = 3) -> list[Candidate]:
    """Up to `per_kind` candidates of each of `kinds`, best first within a kind (kinds
    interleaved: push 1, turn 1, topple 1, push 2, ...). `cloud`, `normals`: (N, 3) world;
    `reachable`: (N,) the points whose pre-contact point the hand can reach from above."""
    for kind in kinds:
        if kind not in KINDS:
            raise InputError(f"planner: unknown primitive kind {kind!r} (known: "
                             f"{', '.join(KINDS)})")
    cloud, normals = np.asarray(cloud, float), np.asarray(normals, float)
    unit_normals = normals / np.maximum(np.linalg.norm(normals, axis=1), 1e-9)[:, None]
    usable = _side(normals) & np.asarray(reachable, bool)
    centre = cloud.mean(axis=0)
    err = goal_errors(pose, goal)
    shift = float(np.linalg.norm(err["shift"]))
    by_kind: dict[str, list[Candidate]] = {k: [] for k in kinds}

    def add(kind, index, direction, length, exact=False):
        by_kind[kind].append(Candidate(kind, int(index), cloud[index].copy(),
                                       unit_normals[index].copy(),
                                       _motion(direction, length, push_distance), exact))

    if "push" in kinds and shift > 1e-3:
        u = np.append(_unit(err["shift"]), 0.0)
        order = _through_centre(cloud, normals, centre, u, usable)
        # The full distance, then half (a push also turns the object: short of the goal is
        # often closer in the task's terms), then the same from the next-best distinct point.
        # One push reaches at most push_distance: half of what it can reach is the variant.
        full = min(shift + GAP, push_distance)
        for scale, rank in ((1.0, 0), (0.5, 0), (1.0, 1)):
            if rank < len(order):
                add("push", order[_distinct(order, cloud, rank)], u[:2], scale * full)
    if "turn" in kinds and abs(err["yaw"]) > 1e-3:
        r = cloud[:, :2] - centre[:2]
        inward = -unit_normals[:, :2]
        torque = r[:, 0] * inward[:, 1] - r[:, 1] * inward[:, 0]  # z of r x f, f unit
        lever = np.sign(err["yaw"]) * torque
        order = np.argsort(-lever)
        order = order[usable[order] & (lever[order] > 0.01)]
        for scale, rank in ((1.0, 0), (0.5, 0), (1.0, 1)):
            if rank < len(order):
                i = order[_distinct(order, cloud, rank)]
                arc = abs(err["yaw"]) * max(lever[i], 0.02)
                add("turn", i, inward[i], scale * arc + GAP)
    if "topple" in kinds and err["tilt"] > TILTED_RAD:
        # The top moves away from where the axis to raise points now (rl/planner docs): a tip
        # about the horizontal axis up_now x z brings up_now to vertical.
        away = -err["up_now"][:2]
        directions = [_unit(away)] if np.linalg.norm(away) > 0.2 else \
            [_unit(err["shift"]) if shift > 1e-3 else np.array([1.0, 0.0]),
             -_unit(err["shift"]) if shift > 1e-3 else np.array([-1.0, 0.0])]
        top = cloud[:, 2].max()
        height = centre[2] + 0.5 * (top - centre[2])
        for u2 in directions:
            order = _through_centre(cloud, normals, centre, np.append(u2, 0.0), usable, height)
            if len(order):
                # Across the object's width and a bit: past the tipping point.
                width = np.ptp(cloud[:, :2] @ u2)
                for scale in (1.0, 0.6):
                    add("topple", order[0], u2, scale * (width + 2 * GAP), exact=True)
    out = []
    for rank in range(per_kind):
        out += [c[rank] for c in by_kind.values() if rank < len(c)]
    return out


def _distinct(order: np.ndarray, cloud: np.ndarray, rank: int, apart: float = 0.02) -> int:
    """The position in `order` of its `rank`-th point at least `apart` from all before it."""
    kept = []
    for position, i in enumerate(order):
        if all(np.linalg.norm(cloud[i] - cloud[order[k]]) >= apart for k in kept):
            kept.append(position)
            if len(kept) > rank:
                return position
    return kept[-1]
