"""The planner's primitive kinds: where to touch the object and which way to move, per kind,
from the object's privileged state (its cloud and normals in the world, its pose, the goal).

Every kind is one primitive of the same executor (systems/control/primitive_executor.py: up over the
object, down to the pre-contact point, a straight push, up again), so the hand only ever moves
through the controller; what a kind chooses is the contact and the motion:

  push    through the centre: a side point whose normal faces away from the goal, pushed
          toward the goal (lowered to push_height like every shipped push, systems/control/low_push.py:
          low, it slides the object instead of tipping it);
  turn    an offset push for yaw: a side point far from the centre whose inward push has the
          largest lever about the vertical through the centre, in the sense that closes the
          yaw error (lowered like a push);
  topple  a side point high above the centre, pushed horizontally across: the object tips
          about its far lower edge onto another face. Offered only when the goal's face is
          not the one down now (the body axis that must end up pointing up is more than
          TILTED_RAD from vertical); the push goes the way that brings that axis up. Aimed at
          the point's own height (`exact`: never lowered, a low push would slide it).

Each kind is one function of the object's state (`Scene`) that returns its candidates best
first, registered in KINDS; rl/planner/sources.py offers each as a candidate source, which takes
the first `per_kind`. A new kind is one function here. Plain numpy: the tests drive it on a box
without a simulator.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from corn_drake.errors import InputError
from corn_drake.rl.envs.branching import Candidate
from corn_drake.transforms import quat_wxyz_to_matrix

# Side faces: a normal at least this horizontal (|n_xy| / |n|), as low_push's HORIZONTAL_MIN.
SIDE = 0.7
# The goal's face counts as down when the axis that must point up is within this of vertical
# (failures.TIPPED_ANGLE_RAD's 0.5 rad: beyond what a push tilts an object on its face).
TILTED_RAD = 0.5
# The hand starts pre_contact_distance off the surface; the fingers are ~1 cm thick, so it
# travels this much before it touches: added to every push's length.
GAP = 0.03


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


@dataclass
class Scene:
    """What every kind reads: the object's cloud and outward unit normals (N, 3, world), which
    points are usable (a side face the hand can reach from above), the cloud's centre, what is
    left to do (goal_errors) and the executor's push_distance."""
    cloud: np.ndarray
    normals: np.ndarray
    usable: np.ndarray
    centre: np.ndarray
    errors: dict
    push_distance: float

    @classmethod
    def of(cls, cloud, normals, pose, goal, push_distance: float, reachable) -> "Scene":
        cloud, normals = np.asarray(cloud, float), np.asarray(normals, float)
        unit = normals / np.maximum(np.linalg.norm(normals, axis=1), 1e-9)[:, None]
        return cls(cloud, unit, _side(normals) & np.asarray(reachable, bool), cloud.mean(axis=0),
                   goal_errors(pose, goal), push_distance)

    @property
    def shift(self) -> float:
        return float(np.linalg.norm(self.errors["shift"]))

    def candidate(self, kind, index, direction, length, exact=False) -> Candidate:
        index = int(index)
        aim = (self.cloud[index].copy(), self.normals[index].copy()) if exact else None
        return Candidate(kind, index, _motion(direction, length, self.push_distance), aim)


def push(scene: Scene) -> list[Candidate]:
    """Through the centre toward the goal: the full distance, then half (a push also turns the
    object: short of the goal is often closer in the task's terms), then the full one from the
    next-best distinct point. One push reaches at most push_distance."""
    if scene.shift <= 1e-3:
        return []
    u = np.append(_unit(scene.errors["shift"]), 0.0)
    order = _through_centre(scene.cloud, scene.normals, scene.centre, u, scene.usable)
    full = min(scene.shift + GAP, scene.push_distance)
    return [scene.candidate("push", order[_distinct(order, scene.cloud, rank)], u[:2],
                            fraction * full)
            for fraction, rank in ((1.0, 0), (0.5, 0), (1.0, 1)) if rank < len(order)]


def turn(scene: Scene) -> list[Candidate]:
    """An offset push with the largest lever about the vertical through the centre, in the
    sense that closes the yaw error: the arc the error asks for, then half of it, then the full
    arc from the next-best distinct point."""
    yaw = scene.errors["yaw"]
    if abs(yaw) <= 1e-3:
        return []
    r = scene.cloud[:, :2] - scene.centre[:2]
    inward = -scene.normals[:, :2]
    torque = r[:, 0] * inward[:, 1] - r[:, 1] * inward[:, 0]  # z of r x f, f unit
    lever = np.sign(yaw) * torque
    order = np.argsort(-lever)
    order = order[scene.usable[order] & (lever[order] > 0.01)]
    out = []
    for fraction, rank in ((1.0, 0), (0.5, 0), (1.0, 1)):
        if rank < len(order):
            i = order[_distinct(order, scene.cloud, rank)]
            arc = abs(yaw) * max(lever[i], 0.02)
            out.append(scene.candidate("turn", i, inward[i], fraction * arc + GAP))
    return out


def topple(scene: Scene) -> list[Candidate]:
    """High on the side, pushed horizontally across the object's width and a bit (past the
    tipping point), aimed exactly; only when the goal has another face down. The top moves
    away from where the axis to raise points now: a tip about the horizontal axis up_now x z
    brings up_now to vertical."""
    errors = scene.errors
    if errors["tilt"] <= TILTED_RAD:
        return []
    away = -errors["up_now"][:2]
    toward = _unit(errors["shift"]) if scene.shift > 1e-3 else np.array([1.0, 0.0])
    directions = [_unit(away)] if np.linalg.norm(away) > 0.2 else [toward, -toward]
    top = scene.cloud[:, 2].max()
    height = scene.centre[2] + 0.5 * (top - scene.centre[2])
    out = []
    for u2 in directions:
        order = _through_centre(scene.cloud, scene.normals, scene.centre, np.append(u2, 0.0),
                                scene.usable, height)
        if len(order):
            width = np.ptp(scene.cloud[:, :2] @ u2)
            out += [scene.candidate("topple", order[0], u2, fraction * (width + 2 * GAP), True)
                    for fraction in (1.0, 0.6)]
    return out


# The analytic kinds, by name (config/choices.PLANNER_SOURCES lists them beside "policy").
KINDS: dict[str, Callable[[Scene], list[Candidate]]] = {"push": push, "turn": turn,
                                                         "topple": topple}


def propose(cloud, normals, pose, goal, push_distance: float, reachable: np.ndarray,
            kinds=tuple(KINDS), per_kind: int = 3) -> list[Candidate]:
    """Up to `per_kind` candidates of each of `kinds`, best first within a kind (kinds
    interleaved: push 1, turn 1, topple 1, push 2, ...). `cloud`, `normals`: (N, 3) world;
    `reachable`: (N,) the points whose pre-contact point the hand can reach from above."""
    for kind in kinds:
        if kind not in KINDS:
            raise InputError(f"planner: unknown primitive kind {kind!r} (known: "
                             f"{', '.join(KINDS)})")
    scene = Scene.of(cloud, normals, pose, goal, push_distance, reachable)
    by_kind = [KINDS[kind](scene)[:per_kind] for kind in kinds]
    return [c[rank] for rank in range(per_kind) for c in by_kind if rank < len(c)]


def _distinct(order: np.ndarray, cloud: np.ndarray, rank: int, apart: float = 0.02) -> int:
    """The position in `order` of its `rank`-th point at least `apart` from all before it."""
    kept = []
    for position, i in enumerate(order):
        if all(np.linalg.norm(cloud[i] - cloud[order[k]]) >= apart for k in kept):
            kept.append(position)
            if len(kept) > rank:
                return position
    return kept[-1]
