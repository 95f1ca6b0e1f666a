"""PrimitiveExecutor: runs one contact primitive at a time through the controller's action input.

A primitive (input `primitive`, PRIMITIVE_DIM): a contact point on the object's cloud (world
frame), its outward surface normal, a push motion in [-1, 1]^3 (times PrimitiveConfig's
push_distance, metres, world frame), the index of the location the policy chose (reported back
for display and tests) and a sequence number. The executor starts a primitive when it is idle
and the input's sequence number is one more than the count of primitives it has started: the
gymnasium env numbers each primitive it sends, and PrimitivePolicySystem always offers
"count + 1", so a finished primitive is never run twice and a new one starts on the next tick.

Phases, one policy period per tick (the same clock as ActionToJointTargets, whose `action`
input this system feeds in place of a PolicySystem):
  approach  up to `clearance` above the object's highest bounding-box corner (straight up when
            below that height), then across to above the pre-contact point. Travelling above
            the object's top is how the hand avoids sweeping it on the way;
  descend   straight down to the pre-contact point (contact point + pre_contact_distance along
            the normal, never lower than min_tool_height above the table). Reaching it within
            reach_tolerance starts the push; approach_steps ticks without reaching it give the
            primitive up (reported unreached) and go to retreat;
  push      the target moves from the pre-contact point by the motion in push_steps equal steps;
  retreat   up by retreat_height over retreat_steps ticks; then idle (done), or first
  settle    (settle_steps > 0 only) hold the hand where it is until no box keypoint of the object
            moved more than settle_motion over the last tick, at most settle_steps ticks: the
            next primitive is chosen from an object at rest, not one still rolling.
Each tick commands the tool toward the phase's target: a translation residual of at most the
controller's max_position_delta (scaled as a whole, so the direction is kept), the rotation
that points the fingers straight down and, for a side contact, turns the hand's narrow side
toward the surface (facing_rotation: the 0.205 m wide palm, 4.5 cm above the tool point, would
otherwise land on the top of a tall object beside a low contact point; the descent waits until
the turn is within turn_tolerance), and the configured stiffness and damping. A contact point
on the object's underside (its pre-contact point below the table) is given up at once.
Physics is the teacher diagram's own: the hand moves only through the controller.

The plan of a tick (next memory, action) is a pure function of the memory (discrete state), the
observation and, when idle, the primitive input; one cache entry computes it, and both the
`action` output (read by the IK latch at the tick) and the periodic update (which stores the
next memory at the same tick) read it, so they always agree.

Outputs: `action` (ACTION_DIM), `status` (STATUS_LAYOUT: phase, ticks in phase, primitives
started, reached, location, pre-contact point, current target) for the env, displays and tests.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import RotationMatrix
from pydrake.systems.framework import BasicVector, LeafSystem, ValueProducer

from corn_drake.config.primitive import PrimitiveConfig
from corn_drake.config.scene import ControllerConfig
from corn_drake.contract import (ACTION_DIM, ACTION_SLICES, NUM_JOINTS, PRIMITIVE_DIM,
                                 PRIMITIVE_LOCATION, PRIMITIVE_MOTION, PRIMITIVE_NORMAL,
                                 PRIMITIVE_POINT, PRIMITIVE_SEQUENCE)
# The `status` output's layout (the contract's), under the names the env and views use.
from corn_drake.contract import PRIMITIVE_STATUS_DIM as STATUS_DIM
from corn_drake.contract import PRIMITIVE_STATUS_LAYOUT as STATUS_LAYOUT
from corn_drake.scene.objects import TABLE_TOP_Z
from corn_drake.systems.observations import ObservationLayout
from corn_drake.timing import PolicyClock
from corn_drake.transforms import from_pose9


IDLE, APPROACH, DESCEND, PUSH, RETREAT, SETTLE = range(6)
PHASES = ("idle", "approach", "descend", "push", "retreat", "settle")

# Memory (discrete state) layout.
_PHASE, _TICKS, _APPROACH_TICKS, _COUNT, _REACHED, _LOCATION = range(6)
_PRE = slice(6, 9)  # pre-contact point
_PUSH = slice(9, 12)  # push displacement (m)
_Z_SAFE = 12
_ANCHOR = slice(13, 16)  # where the retreat started
_TARGET = slice(16, 19)  # the last commanded target
_FACING = slice(19, 21)  # the contact normal's horizontal direction (zeros: a top contact)
_LEAN = 21  # the fingers' lean toward the surface for this primitive (rad; facing_rotation)
_KEYPOINTS = slice(22, 46)  # the object's box keypoints at the last tick (settle's motion)
_MEMORY_SIZE = 46

# The palm's lower edge (the finger knuckles) is this far above the tool point: an object whose
# top is lower than that at the pre-contact point cannot meet the palm, and the fingers stay
# vertical for it (leaning, their lower corners come within ~2 mm of the table at the lowest
# pre-contact points: a flat book or plate was then never reached).
PALM_ABOVE_TOOL = 0.045


_DOWN = np.array([0.0, 0.0, -1.0])


def make_primitive(point, normal, motion, location: int, sequence: int) -> np.ndarray:
    """The `primitive` input vector (PRIMITIVE_DIM) of one primitive."""
    out = np.zeros(PRIMITIVE_DIM)
    out[PRIMITIVE_POINT], out[PRIMITIVE_NORMAL] = point, normal
    out[PRIMITIVE_MOTION] = np.clip(motion, -1.0, 1.0)
    out[PRIMITIVE_LOCATION], out[PRIMITIVE_SEQUENCE] = location, sequence
    return out


def facing_rotation(R_tool: np.ndarray, facing: np.ndarray, tilt: float = 0.0) -> np.ndarray:
    """The tool rotation a primitive holds: fingers straight down and, for a side contact
    (`facing`, the normal's horizontal unit direction; zeros for a top contact), the hand's
    narrow side (its x axis: the palm is 0.063 m deep along x, 0.205 m wide along y) toward
    the surface, so the wide palm, 4.5 cm above the tool point, passes beside the object
    instead of landing on its top. Of the two such yaws, the one nearer the current.

    `tilt` (rad, side contacts only): the fingers lean that far from vertical toward the
    surface, so the palm leans away from it. Why: the palm is 2.1 cm deeper than the fingers
    along x, so with vertical fingers it meets the object before they do, 4.5-10 cm above the
    tool point, and a push there tips a tall object however low the fingers are; a 30 degree
    lean moves the palm's lower edge 2.25 cm back."""
    R = fingers_down(R_tool)
    if not np.any(facing):
        return R
    x = np.array([facing[0], facing[1], 0.0])
    if x @ R[:, 0] < 0:
        x = -x
    if tilt == 0.0:  # the rotation as it always was, bit for bit (shipped cards replay)
        z = _DOWN
        return np.column_stack([x, np.cross(z, x), z])
    toward = -np.array([facing[0], facing[1], 0.0]) / np.linalg.norm(facing)
    z = np.cos(tilt) * _DOWN + np.sin(tilt) * toward
    x = x - (x @ z) * z
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def fingers_down(R_tool: np.ndarray) -> np.ndarray:
    """The rotation nearest R_tool whose z axis (the fingers' direction) points straight down:
    R_tool turned about the axis z x down by the angle between them (yaw kept)."""
    z = R_tool[:, 2]
    axis = np.cross(z, _DOWN)
    s, c = np.linalg.norm(axis), float(z @ _DOWN)
    if s < 1e-9:
        if c > 0:
            return R_tool
        axis = R_tool[:, 0]  # pointing straight up: turn half a turn about the tool's x
        s = 1.0
    angle = np.arctan2(s, c)
    return RotationMatrix(AngleAxis(angle, axis / np.linalg.norm(axis))).matrix() @ R_tool


def reachable_from_above(point_z, normal_z, cfg: PrimitiveConfig):
    """Whether a contact point (its height, its unit normal's z) has its pre-contact point above
    the table. One below it (a point on the object's underside) would, raised above the table,
    lie inside the object, and the hand would press on the object from above: the executor
    gives such a primitive up at once, and the policy never chooses one (its location mask,
    rl/primitive/agent.py). Plain arithmetic: floats, numpy arrays or torch tensors."""
    natural = point_z + cfg.pre_contact_distance * normal_z
    return natural >= TABLE_TOP_Z + cfg.min_tool_height - cfg.reach_tolerance


def pre_contact_point(point, normal, cfg: PrimitiveConfig) -> np.ndarray:
    """Where the descent ends for a contact point: pre_contact_distance off it along its unit
    normal (straight up for a zero normal), never lower than min_tool_height over the table."""
    n = np.asarray(normal, float)
    norm = np.linalg.norm(n)
    n = n / norm if norm > 1e-9 else np.array([0.0, 0.0, 1.0])
    pre = np.asarray(point, float) + cfg.pre_contact_distance * n
    pre[2] = max(pre[2], TABLE_TOP_Z + cfg.min_tool_height)
    return pre


class PrimitivePlanner:
    """The executor's tick as plain numpy: `plan(memory, tool_p, tool_R, top_z, primitive)` ->
    (next memory, action). Kept apart from the LeafSystem so tests can drive it directly."""

    def __init__(self, cfg: PrimitiveConfig, controller: ControllerConfig):
        self.cfg, self.controller = cfg, controller
        self._tilt = np.deg2rad(cfg.finger_tilt_deg)
        self._gains = np.concatenate([np.full(NUM_JOINTS, cfg.stiffness),
                                      np.full(NUM_JOINTS, cfg.damping)])

    @staticmethod
    def initial_memory() -> np.ndarray:
        m = np.zeros(_MEMORY_SIZE)
        m[_REACHED], m[_LOCATION] = -1.0, -1.0
        return m

    def pre_contact(self, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
        return pre_contact_point(point, normal, self.cfg)

    def _start(self, m: np.ndarray, primitive: np.ndarray, top_z: float) -> None:
        cfg = self.cfg
        pre = self.pre_contact(primitive[PRIMITIVE_POINT], primitive[PRIMITIVE_NORMAL])
        m[_PHASE], m[_TICKS], m[_APPROACH_TICKS] = APPROACH, 0, 0
        m[_COUNT] += 1
        m[_REACHED], m[_LOCATION] = -1.0, primitive[PRIMITIVE_LOCATION]
        m[_PRE] = pre
        m[_PUSH] = np.clip(primitive[PRIMITIVE_MOTION], -1.0, 1.0) * cfg.push_distance
        m[_Z_SAFE] = max(top_z, pre[2]) + cfg.clearance
        normal = np.asarray(primitive[PRIMITIVE_NORMAL], float)
        horizontal = np.linalg.norm(normal[:2])
        m[_LEAN] = self._tilt if top_z > pre[2] + PALM_ABOVE_TOOL else 0.0
        m[_FACING] = normal[:2] / horizontal if horizontal > 0.3 * np.linalg.norm(normal) \
            else 0.0
        if not reachable_from_above(primitive[PRIMITIVE_POINT][2],
                                    normal[2] / max(np.linalg.norm(normal), 1e-9), cfg):
            m[_REACHED] = 0.0
            self._enter(m, RETREAT)

    def _enter(self, m: np.ndarray, phase: int) -> None:
        m[_PHASE], m[_TICKS] = phase, 0

    def plan(self, memory: np.ndarray, tool_p: np.ndarray, tool_R: np.ndarray, top_z: float,
             primitive, keypoints=None) -> tuple[np.ndarray, np.ndarray]:
        """`primitive`: a callable giving the primitive input (evaluated only when idle);
        `keypoints`: the object's 8 box keypoints, world frame (needed with settle_steps)."""
        cfg, m = self.cfg, np.array(memory, float)
        tol = cfg.reach_tolerance
        if cfg.settle_steps and keypoints is None:
            raise ValueError("primitive.settle_steps needs the object's keypoints")
        # Settling ends after a tick over which the object hardly moved (judged here, against
        # the keypoints stored at the last tick, and acted on at the tick's end like the
        # fixed-length phases, so the next primitive starts at an idle tick, as displays and
        # PrimitivePolicySystem's record expect).
        still = m[_PHASE] == SETTLE and np.linalg.norm(
            np.asarray(keypoints, float).reshape(-1, 3) - m[_KEYPOINTS].reshape(-1, 3),
            axis=1).max() < cfg.settle_motion
        if keypoints is not None:
            m[_KEYPOINTS] = np.asarray(keypoints, float).reshape(-1)
        if m[_PHASE] == IDLE:
            offered = np.asarray(primitive(), float)
            if round(offered[PRIMITIVE_SEQUENCE]) == round(m[_COUNT]) + 1:
                self._start(m, offered, top_z)
        # Transitions that depend on where the tool is now (checked before commanding).
        if m[_PHASE] == APPROACH:
            above = np.array([m[_PRE][0], m[_PRE][1], m[_Z_SAFE]])
            turned = RotationMatrix(facing_rotation(tool_R, m[_FACING], m[_LEAN]) @ tool_R.T
                                    ).ToAngleAxis().angle() < cfg.turn_tolerance
            if tool_p[2] >= m[_Z_SAFE] - tol and np.linalg.norm(tool_p[:2] - above[:2]) < tol \
                    and turned:
                self._enter(m, DESCEND)
        if m[_PHASE] == DESCEND and np.linalg.norm(tool_p - m[_PRE]) < tol:
            m[_REACHED] = 1.0
            self._enter(m, PUSH)
        if m[_PHASE] in (APPROACH, DESCEND) and m[_APPROACH_TICKS] >= cfg.approach_steps:
            m[_REACHED] = 0.0
            self._enter(m, RETREAT)
        # The target of this tick.
        phase = int(m[_PHASE])
        if phase in (IDLE, SETTLE):
            target = tool_p.copy()  # hold where the hand is
        elif phase == APPROACH:
            if tool_p[2] < m[_Z_SAFE] - tol:
                target = np.array([tool_p[0], tool_p[1], m[_Z_SAFE]])  # straight up first
            else:
                target = np.array([m[_PRE][0], m[_PRE][1], m[_Z_SAFE]])
        elif phase == DESCEND:
            target = m[_PRE].copy()
        elif phase == PUSH:
            target = m[_PRE] + m[_PUSH] * (m[_TICKS] + 1) / cfg.push_steps
        else:  # RETREAT
            if m[_TICKS] == 0:
                m[_ANCHOR] = tool_p
            target = m[_ANCHOR] + np.array([0.0, 0.0, cfg.retreat_height]) * (
                (m[_TICKS] + 1) / cfg.retreat_steps)
        target[2] = max(target[2], TABLE_TOP_Z + cfg.min_tool_height)
        m[_TARGET] = target
        action = self._action(target, tool_p, tool_R,
                              m[_FACING] if phase not in (IDLE, SETTLE) else np.zeros(2),
                              m[_LEAN])
        # Count this tick; phases with a fixed length move on after their last command, so the
        # memory after a primitive's last retreat tick already says idle or settle (the env
        # stops at idle).
        m[_TICKS] += 1
        if phase in (APPROACH, DESCEND):
            m[_APPROACH_TICKS] += 1
        if phase == PUSH and m[_TICKS] >= cfg.push_steps:
            self._enter(m, RETREAT)
        elif phase == RETREAT and m[_TICKS] >= cfg.retreat_steps:
            self._enter(m, SETTLE if cfg.settle_steps else IDLE)
        elif phase == SETTLE and (still or m[_TICKS] >= cfg.settle_steps):
            self._enter(m, IDLE)
        return m, action

    def _action(self, target: np.ndarray, tool_p: np.ndarray, tool_R: np.ndarray,
                facing: np.ndarray, lean: float) -> np.ndarray:
        ctrl = self.controller
        action = np.zeros(ACTION_DIM)
        move = (target - tool_p) / ctrl.max_position_delta
        action[ACTION_SLICES["position"]] = move / max(1.0, np.abs(move).max())
        held = facing_rotation(tool_R, facing, lean)
        rotvec = RotationMatrix(held @ tool_R.T).ToAngleAxis()
        turn = rotvec.axis() * rotvec.angle() / ctrl.max_rotation_delta
        action[ACTION_SLICES["rotation"]] = turn / max(1.0, np.abs(turn).max())
        action[ACTION_SLICES["kp"]] = self._gains[:NUM_JOINTS]
        action[ACTION_SLICES["rho"]] = self._gains[NUM_JOINTS:]
        return action


def memory_status(memory: np.ndarray) -> np.ndarray:
    """The `status` output (STATUS_LAYOUT) of a memory vector."""
    out = np.zeros(STATUS_DIM)
    out[0], out[1], out[2] = memory[_PHASE], memory[_TICKS], memory[_COUNT]
    out[3], out[4] = memory[_REACHED], memory[_LOCATION]
    out[STATUS_LAYOUT["pre_contact"]] = memory[_PRE]
    out[STATUS_LAYOUT["target"]] = memory[_TARGET]
    out[STATUS_LAYOUT["push"]] = memory[_PUSH]
    return out


def top_height(keypoints: np.ndarray) -> float:
    """The highest bounding-box corner (the observation's object_keypoints, world frame)."""
    return float(np.asarray(keypoints).reshape(-1, 3)[:, 2].max())


class PrimitiveExecutor(LeafSystem):
    """Inputs: `observation` (TeacherObservations' packed output), `primitive` (PRIMITIVE_DIM).
    Outputs: `action` (ACTION_DIM, to ActionToJointTargets), `status` (STATUS_DIM)."""

    def __init__(self, cfg: PrimitiveConfig, controller: ControllerConfig, clock: PolicyClock,
                 num_points: int):
        super().__init__()
        self.planner = PrimitivePlanner(cfg, controller)
        self._layout = ObservationLayout(num_points)
        self._obs = self.DeclareVectorInputPort("observation", self._layout.size)
        self._primitive = self.DeclareVectorInputPort("primitive", PRIMITIVE_DIM)
        self._memory = self.DeclareDiscreteState(PrimitivePlanner.initial_memory())
        self._plan = self.DeclareCacheEntry(
            "tick plan: (next memory, action)",
            ValueProducer(allocate=lambda: AbstractValue.Make((None, None)), calc=self._calc_plan),
            {self.discrete_state_ticket(self._memory),
             self.input_port_ticket(self._obs.get_index()),
             self.input_port_ticket(self._primitive.get_index())})
        self.DeclarePeriodicDiscreteUpdateEvent(clock.period, clock.offset, self._update)
        self.DeclareVectorOutputPort("action", ACTION_DIM, self._calc_action,
                                     {self._plan.ticket()})
        self.DeclareVectorOutputPort("status", STATUS_DIM, self._calc_status,
                                     {self.discrete_state_ticket(self._memory)})

    def reset(self, context) -> None:
        """Idle, no primitive started (the episode's start); `context` is this system's."""
        context.SetDiscreteState(self._memory, PrimitivePlanner.initial_memory())

    def _calc_plan(self, context, value):
        obs = self._obs.Eval(context)
        s = self._layout.slices
        tool_p, tool_R = from_pose9(obs[s["hand_state"]])
        keypoints = np.asarray(obs[s["object_keypoints"]]).reshape(-1, 3)
        value.set_value(self.planner.plan(
            context.get_discrete_state(self._memory).value(), tool_p, tool_R,
            top_height(keypoints), lambda: self._primitive.Eval(context), keypoints))

    def _update(self, context, discrete_state):
        discrete_state.set_value(self._memory, self._plan.Eval(context)[0])

    def _calc_action(self, context, output: BasicVector):
        output.SetFromVector(self._plan.Eval(context)[1])

    def _calc_status(self, context, output: BasicVector):
        output.SetFromVector(memory_status(context.get_discrete_state(self._memory).value()))

