"""AttentionView: the policy's attention painted on the object's cloud in Meshcat, every step.

Inputs: `point_attention` (each cloud point's patch score, PolicySystem's output of that name)
and `cloud` (the same observation's cloud, world frame, flattened). At every policy boundary
(the instant the policy reads its observation and chooses the action) it draws the cloud as a
Meshcat point cloud coloured viridis by score / the step's highest score: the patch the policy
attends to most is yellow, patches it ignores are dark purple.

Recordings: Meshcat animations hold transforms and properties but not SetObject (Drake's
Meshcat.StartRecording says so: an object is always sent at once, never recorded), so one path
redrawn every step would leave only the last step's colours in an HTML recording. Each step is
therefore its own object, `<path>/step_NNNN`, and its "visible" property is recorded: hidden
from time 0, shown at its step, hidden at the next one (three.js holds a track's first key
before it, so every step but the first needs the "hidden from 0" key). Outside a recording the same calls
simply show the newest step and hide the one before, so a live viewer sees the current step
only. Every episode starts by deleting `<path>` (an initialization event), so steps of an
earlier episode never show in a later one.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.perception import BaseField, Fields, PointCloud
from pydrake.systems.framework import LeafSystem

from corn_drake.contract import POSITION_DIM
from corn_drake.timing import PolicyClock

DEFAULT_PATH = "/attention"


def viridis_rgb(scores: np.ndarray) -> np.ndarray:
    """(N,) scores -> (N, 3) uint8 viridis colours of score / max(scores) (all dark when every
    score is 0)."""
    from matplotlib import colormaps

    scores = np.asarray(scores, float)
    if scores.ndim != 1 or not np.isfinite(scores).all() or (scores < 0).any():
        raise ValueError(f"scores must be finite and >= 0, one per point, got shape "
                         f"{scores.shape} with min {scores.min() if scores.size else None}")
    top = scores.max() if scores.size else 0.0
    relative = scores / top if top > 0 else np.zeros_like(scores)
    return np.round(255 * colormaps["viridis"](relative)[:, :3]).astype(np.uint8)


def step_path(path: str, step: int) -> str:
    """Meshcat path of the cloud drawn at policy step `step`."""
    return f"{path}/step_{step:04d}"


class AttentionView(LeafSystem):
    def __init__(self, meshcat: Meshcat, num_points: int, clock: PolicyClock,
                 path: str = DEFAULT_PATH, point_size: float = 0.006):
        super().__init__()
        self._meshcat, self._clock, self._path = meshcat, clock, path
        self._num_points, self._point_size = num_points, point_size
        self._scores = self.DeclareVectorInputPort("point_attention", num_points)
        self._cloud = self.DeclareVectorInputPort("cloud", POSITION_DIM * num_points)
        # At the policy boundaries, where the policy latches its action: the inputs then hold
        # the observation that action was chosen from.
        self.DeclarePeriodicPublishEvent(clock.period, clock.offset, self._draw)
        self.DeclareInitializationPublishEvent(self._start)

    @property
    def path(self) -> str:
        return self._path

    def step_of(self, time: float) -> int:
        """The policy step whose boundary is at `time`."""
        return max(0, round((time - self._clock.offset) / self._clock.period))

    def _start(self, context):
        self._meshcat.Delete(self._path)
        self._draw(context)  # the first step too, whichever of the two events runs first

    def _draw(self, context):
        t, k = context.get_time(), self.step_of(context.get_time())
        cloud = PointCloud(self._num_points, Fields(BaseField.kXYZs | BaseField.kRGBs))
        cloud.mutable_xyzs()[:] = self._cloud.Eval(context).reshape(-1, POSITION_DIM).T
        cloud.mutable_rgbs()[:] = viridis_rgb(self._scores.Eval(context)).T
        here = step_path(self._path, k)
        self._meshcat.SetObject(here, cloud, point_size=self._point_size)
        if k > 0:
            before = step_path(self._path, k - 1)
            self._meshcat.SetProperty(here, "visible", False, 0.0)  # recorded: hidden until k
            self._meshcat.SetProperty(before, "visible", False)  # live (recording or not)
            # Recorded: the step before shows from its boundary to this one. Its own draw may
            # not have been recorded: step 0 is drawn when the episode is initialised, before
            # run_episode starts the recording.
            self._meshcat.SetProperty(before, "visible", True, self._clock.boundary(k - 1))
            self._meshcat.SetProperty(before, "visible", False, t)
        self._meshcat.SetProperty(here, "visible", True, t)


def add_attention_view(builder, policy, cloud_port, meshcat: Meshcat, num_points: int,
                       clock: PolicyClock, path: str = DEFAULT_PATH) -> AttentionView:
    """Adds an AttentionView named "attention_view" fed by `policy`'s point_attention output
    (a PolicySystem built with attention=True) and `cloud_port` (the observation's cloud)."""
    view = builder.AddNamedSystem("attention_view", AttentionView(meshcat, num_points, clock, path))
    builder.Connect(policy.GetOutputPort("point_attention"), view.GetInputPort("point_attention"))
    builder.Connect(cloud_port, view.GetInputPort("cloud"))
    return view
