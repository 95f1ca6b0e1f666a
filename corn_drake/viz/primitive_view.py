"""PrimitiveView: the contact-primitive policy's choices drawn in Meshcat, one primitive at a time.

For every primitive the executor starts it draws, under `<path>/primitive_NNN` (NNN: the
executor's count of primitives started, 1 for the first):
  contact  a small red sphere at the chosen contact point;
  arrow    the push as the executor runs it, from the pre-contact point to where the push ends
           (both from the executor's status: the motion scaled by push_distance);
  scores   with a policy in the diagram: the object's cloud coloured viridis by the policy's score
           of each point's candidate location (its nearest patch centre), lowest dark purple,
           highest yellow.
Where the contact point comes from: with a policy, its held `choice` (the cloud index, recorded
at the tick the executor took the primitive) and the cloud; without one (the gymnasium env), the
executor's `primitive` input, which the env fixes for each primitive.

Timing: the view looks at the executor's status at every policy boundary, where a publish sees
the state before that boundary's update: a count that went up since the last look means a
primitive started one period earlier, at the previous boundary. Only then does it draw, so an
episode costs one drawing per primitive, not per step; it keeps the count it last drew (and
when that primitive started) in plain attributes, which only its drawing reads.

Recordings: as in viz/attention_view.py, Meshcat records transforms and properties but never
SetObject, so each primitive is its own group whose "visible" property is recorded: hidden from
time 0, shown from the tick the primitive started until the next one starts. Live, the newest
primitive is shown and the one before hidden. Every episode starts by deleting `<path>` (an
initialization event), so an earlier episode's primitives never show in a later one.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import Cylinder, Meshcat, MeshcatCone, Rgba, Sphere
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.perception import BaseField, Fields, PointCloud
from pydrake.systems.framework import LeafSystem

from corn_drake.contract import POSITION_DIM
from corn_drake.systems.control.primitive_executor import (PRIMITIVE_DIM, PRIMITIVE_POINT,
                                                           STATUS_DIM, STATUS_LAYOUT)
from corn_drake.timing import PolicyClock
from corn_drake.viz.attention_view import viridis_rgb

DEFAULT_PATH = "/primitive"
CONTACT_RGBA = Rgba(0.9, 0.1, 0.1, 1.0)
ARROW_RGBA = Rgba(1.0, 0.55, 0.0, 1.0)
CONTACT_RADIUS = 0.008  # m
SHAFT_RADIUS = 0.003
HEAD_LENGTH, HEAD_RADIUS = 0.015, 0.008
POINT_SIZE = 0.006


def primitive_path(path: str, count: int) -> str:
    """Meshcat group of the `count`-th primitive of an episode (1 for the first)."""
    return f"{path}/primitive_{count:03d}"


def nearest_locations(cloud: np.ndarray, num_locations: int) -> np.ndarray:
    """(N,) index of each cloud point's candidate location among the policy's `num_locations`:
    its nearest patch centre, the centres being the cloud's farthest-point samples exactly as
    the policy's features pick them (nn/patchify: deterministic, from point 0)."""
    import torch

    from corn_drake.nn.encoders.patchify import farthest_point_sample

    cloud = np.asarray(cloud, np.float32).reshape(-1, POSITION_DIM)
    if not 1 <= num_locations < len(cloud):
        raise ValueError(f"num_locations must be in [1, {len(cloud)}], got {num_locations}")
    points = torch.from_numpy(cloud)[None]
    centres = farthest_point_sample(points, num_locations)[0].numpy()
    distance = np.linalg.norm(cloud[:, None] - cloud[centres][None], axis=-1)
    return distance.argmin(axis=1)


def _frame_along(start: np.ndarray, direction: np.ndarray) -> RigidTransform:
    """A frame at `start` whose z axis is `direction` (unit): shapes along z point that way."""
    return RigidTransform(RotationMatrix.MakeFromOneVector(direction, 2), start)


class PrimitiveView(LeafSystem):
    """Inputs: `executor_status` (STATUS_DIM), `cloud` (3N, the observation's, world frame) and
    either `choice` (the policy's CHOICE_DIM) and `scores` (its L location scores), when
    `num_locations` is given, or `primitive` (the executor's PRIMITIVE_DIM input)."""

    def __init__(self, meshcat: Meshcat, clock: PolicyClock, num_points: int,
                 num_locations: int | None = None, path: str = DEFAULT_PATH):
        super().__init__()
        from corn_drake.systems.policies.primitive_policy import CHOICE_DIM

        self._meshcat, self._clock, self._path = meshcat, clock, path
        self._num_points = num_points
        self._num_locations = num_locations
        self._status = self.DeclareVectorInputPort("executor_status", STATUS_DIM)
        self._cloud = self.DeclareVectorInputPort("cloud", POSITION_DIM * num_points)
        if num_locations is None:
            self._primitive = self.DeclareVectorInputPort("primitive", PRIMITIVE_DIM)
        else:
            self._choice = self.DeclareVectorInputPort("choice", CHOICE_DIM)
            self._scores = self.DeclareVectorInputPort("scores", num_locations)
        self.DeclarePeriodicPublishEvent(clock.period, clock.offset, self._look)
        self.DeclareInitializationPublishEvent(self._start)
        self._drawn = (0, 0.0)  # (count of the primitive last drawn, the time it started)

    @property
    def path(self) -> str:
        return self._path

    def _start(self, context):
        self._meshcat.Delete(self._path)
        self._drawn = (0, 0.0)

    def _look(self, context):
        status = self._status.Eval(context)
        count = int(round(status[STATUS_LAYOUT["count"]]))
        if count <= self._drawn[0]:
            return
        # The executor took it at the previous boundary (this publish sees the state before
        # this boundary's update); at the episode's first boundary nothing can have started.
        started = max(self._clock.offset, context.get_time() - self._clock.period)
        cloud = self._cloud.Eval(context).reshape(-1, POSITION_DIM)
        here = primitive_path(self._path, count)
        self._draw(here, context, status, cloud)
        self._meshcat.SetProperty(here, "visible", False, 0.0)  # recorded: hidden until it starts
        self._meshcat.SetProperty(here, "visible", True, started)
        previous, previous_start = self._drawn
        if previous > 0:
            before = primitive_path(self._path, previous)
            self._meshcat.SetProperty(before, "visible", False)  # live
            # Recorded: shown from its start (again, in case the recording began after it was
            # drawn) to this primitive's start.
            self._meshcat.SetProperty(before, "visible", True, previous_start)
            self._meshcat.SetProperty(before, "visible", False, started)
        self._meshcat.SetProperty(here, "visible", True)  # live
        self._drawn = (count, started)

    def _draw(self, here: str, context, status: np.ndarray, cloud: np.ndarray) -> None:
        if self._num_locations is None:
            contact = self._primitive.Eval(context)[PRIMITIVE_POINT]
        else:
            choice = self._choice.Eval(context)
            index = int(round(choice[0]))
            contact = cloud[index] if 0 <= index < len(cloud) else None
            self._draw_scores(f"{here}/scores", cloud, self._scores.Eval(context))
        if contact is not None:
            self._meshcat.SetObject(f"{here}/contact", Sphere(CONTACT_RADIUS), CONTACT_RGBA)
            self._meshcat.SetTransform(f"{here}/contact", RigidTransform(np.asarray(contact)))
        self._draw_arrow(f"{here}/arrow", status[STATUS_LAYOUT["pre_contact"]],
                         status[STATUS_LAYOUT["push"]])

    def _draw_arrow(self, path: str, start: np.ndarray, push: np.ndarray) -> None:
        length = float(np.linalg.norm(push))
        if length < 1e-4:  # no push to show: the contact point alone says where it goes
            return
        direction = push / length
        head = min(HEAD_LENGTH, length)
        shaft = length - head
        if shaft > 1e-4:
            self._meshcat.SetObject(f"{path}/shaft", Cylinder(SHAFT_RADIUS, shaft), ARROW_RGBA)
            self._meshcat.SetTransform(f"{path}/shaft",
                                       _frame_along(start + direction * shaft / 2, direction))
        # The cone's apex is its origin and it opens along its +z: apex at the push's end,
        # opening back toward the start.
        self._meshcat.SetObject(f"{path}/head", MeshcatCone(head, HEAD_RADIUS, HEAD_RADIUS),
                                ARROW_RGBA)
        self._meshcat.SetTransform(f"{path}/head", _frame_along(start + push, -direction))

    def _draw_scores(self, path: str, cloud: np.ndarray, scores: np.ndarray) -> None:
        scores = np.asarray(scores, float)
        per_point = scores[nearest_locations(cloud, len(scores))]
        drawn = PointCloud(len(cloud), Fields(BaseField.kXYZs | BaseField.kRGBs))
        drawn.mutable_xyzs()[:] = cloud.T
        # Critic scores may be negative: colour by where each lies between the lowest and the
        # highest of this choice.
        drawn.mutable_rgbs()[:] = viridis_rgb(per_point - per_point.min()).T
        self._meshcat.SetObject(path, drawn, point_size=POINT_SIZE)


def add_primitive_view(builder, handles, meshcat: Meshcat, clock: PolicyClock,
                       path: str = DEFAULT_PATH) -> PrimitiveView:
    """Adds a PrimitiveView named "primitive_view" to the primitive diagram being built
    (builders/primitive.py; `handles`: its PrimitiveDiagram). With a policy (handles.policy) it
    reads the policy's `choice` and `scores`; without one, the diagram's exported
    `executor.primitive` input, which must already be exported."""
    teacher = handles.teacher
    cloud = teacher.observations.GetOutputPort("cloud")
    num_points = cloud.size() // POSITION_DIM
    policy = handles.policy
    num_locations = None if policy is None else policy.GetOutputPort("scores").size()
    view = builder.AddNamedSystem("primitive_view", PrimitiveView(
        meshcat, clock, num_points, num_locations, path))
    builder.Connect(handles.executor.GetOutputPort("status"), view.GetInputPort("executor_status"))
    builder.Connect(cloud, view.GetInputPort("cloud"))
    if policy is None:
        builder.ConnectInput("executor.primitive", view.GetInputPort("primitive"))
    else:
        for port in ("choice", "scores"):
            builder.Connect(policy.GetOutputPort(port), view.GetInputPort(port))
    return view
