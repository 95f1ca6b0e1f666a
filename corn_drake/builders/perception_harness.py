"""A kinematic harness around the student diagram's perception chain.

Tests, benchmarks and notebook 05 pose the robot and the object directly in the plant context
(no physics) and ask the chain for its outputs, so each frame costs only what perception costs.
"""

from __future__ import annotations

import time

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from corn_drake.config.student import StudentDiagramConfig
from corn_drake.contract import ACTION_DIM
from corn_drake.builders.student import StudentDiagram, build_student_diagram
from corn_drake.config.plumbing.diagram_files import load_student_config
from corn_drake.scene.objects import TABLE_TOP_Z, ObjectSpec
from corn_drake.systems.perception.pose_tracker import TrackerState, pose_error
from corn_drake.systems.perception.segmentation import SegmentationStats
from corn_drake.timing import clock_of

# An arm pose with the hand above the table's near half: in view of all three cameras.
ARM_IN_VIEW = np.array([0.0, 0.3, 0.0, -2.0, 0.0, 2.4, 0.8])


class PerceptionHarness:
    def __init__(self, cfg: StudentDiagramConfig | None = None, spec: ObjectSpec | None = None,
                 meshcat=None):
        self.cfg = cfg or load_student_config()
        self.student: StudentDiagram = build_student_diagram(self.cfg, spec, meshcat)
        self.diagram = self.student.diagram
        self.scene = self.student.scene
        self.per = self.student.perception
        self.context = self.diagram.CreateDefaultContext()
        self.diagram.GetInputPort("controller.action").FixValue(self.context, np.zeros(ACTION_DIM))
        self.plant_context = self.scene.plant.GetMyMutableContextFromRoot(self.context)
        self.tracker_context = self.per.tracker.GetMyMutableContextFromRoot(self.context)
        self.seg_context = self.per.segmentation.GetMyContextFromRoot(self.context)
        self.object_label = int(self.scene.object_body.index())
        self.set_robot(ARM_IN_VIEW)

    @property
    def frame_period(self) -> float:
        """Seconds between two tracker updates: one policy step."""
        return clock_of(self.cfg.teacher.scene.physics).period

    # --- posing ------------------------------------------------------------------------------
    def set_robot(self, q) -> None:
        self.scene.plant.SetPositions(self.plant_context, self.scene.panda, np.asarray(q, float))

    def set_object(self, X: RigidTransform) -> None:
        self.scene.plant.SetFreeBodyPose(self.plant_context, self.scene.object_body, X)

    def object_pose(self) -> np.ndarray:
        return self.scene.plant.EvalBodyPoseInWorld(
            self.plant_context, self.scene.object_body).GetAsMatrix4()

    # --- images and clouds -------------------------------------------------------------------
    def depth_images(self) -> list[np.ndarray]:
        return self.per.rig.depth_images(self.context)

    def labels(self) -> np.ndarray:
        """Render labels of the merged cloud's points (camera after camera, row-major pixels)."""
        return np.concatenate([p.Eval(s.GetMyContextFromRoot(self.context)).data.reshape(-1)
                               for p, s in zip(self.per.rig.label_ports(), self.per.rig.sensors)])

    def merged_points(self) -> np.ndarray:
        return self.per.segmentation.merged_points(self.seg_context)

    def segment_indices(self, stats: SegmentationStats | None = None) -> np.ndarray:
        return self.per.segmentation.segment_indices(self.seg_context, stats)

    def segmented_cloud(self) -> np.ndarray:
        return self.per.segmentation.GetOutputPort("object_cloud").Eval(self.seg_context).xyzs().T

    def precision_recall(self) -> dict:
        """Segmentation against the label image: recall of object pixels, non-object fraction."""
        labels, idx = self.labels(), self.segment_indices()
        obj = labels == self.object_label
        tp = int(obj[idx].sum())
        return {"object_points": int(obj.sum()), "kept": int(len(idx)),
                "recall": tp / max(int(obj.sum()), 1),
                "non_object_fraction": (len(idx) - tp) / max(len(idx), 1)}

    # --- tracking ----------------------------------------------------------------------------
    def reset_tracker(self) -> None:
        self.per.tracker.reset(self.tracker_context)

    def track(self) -> TrackerState:
        """One tracker update on the current scene (the event the simulator would run)."""
        self.per.tracker.ExecuteForcedEvents(self.tracker_context)
        return self.per.tracker.tracker_state(self.tracker_context)

    def stage_times(self) -> dict[str, float]:
        """Runs the chain once on the current scene, stage by stage; seconds per stage."""
        ctx, per = self.context, self.per
        t0 = time.perf_counter()
        for p, s in zip(per.rig.depth_ports(), per.rig.sensors):
            p.Eval(s.GetMyContextFromRoot(ctx))
        t1 = time.perf_counter()
        for c in per.rig.to_cloud:
            c.point_cloud_output_port().Eval(c.GetMyContextFromRoot(ctx))
        t2 = time.perf_counter()
        per.segmentation.GetOutputPort("object_cloud").Eval(self.seg_context)
        t3 = time.perf_counter()
        per.tracker.ExecuteForcedEvents(self.tracker_context)
        t4 = time.perf_counter()
        return {"render": t1 - t0, "depth_to_cloud": t2 - t1, "segmentation": t3 - t2,
                "tracking": t4 - t3}


def resting_pose(spec: ObjectSpec, xy, yaw: float, on_side: bool = False) -> RigidTransform:
    """The spec's first stable pose (or a cylinder on its side) at (x, y) turned by yaw."""
    if on_side:
        R0 = RotationMatrix(RollPitchYaw(np.pi / 2, 0.0, 0.0))
        z = TABLE_TOP_Z + spec.primitive[1][0]
    else:
        R0 = RigidTransform(RotationMatrix.Identity()).rotation()
        from corn_drake.transforms import quat_wxyz_to_matrix

        R0 = RotationMatrix(quat_wxyz_to_matrix(spec.stable_poses[0][3:]))
        z = spec.stable_poses[0][2]
    return RigidTransform(RotationMatrix(RollPitchYaw(0.0, 0.0, yaw)) @ R0, [xy[0], xy[1], z])


def slide_and_turn_poses(spec: ObjectSpec, duration: float = 10.0, period: float = 0.1,
                  start=(-0.08, 0.06), shift=(0.15, -0.10), turn: float = 1.2,
                  on_side: bool = False) -> list[RigidTransform]:
    """A kinematic pose sequence (no controller, no physics) of the object resting on the table
    while it slides by `shift` and turns by `turn` rad, as a push would move it.

    Smooth start and stop (smoothstep), so the speed peaks at 1.5x its mean mid-push.
    """
    poses = []
    for k in range(int(round(duration / period)) + 1):
        s = k * period / duration
        s = s * s * (3 - 2 * s)
        xy = np.asarray(start) + s * np.asarray(shift)
        poses.append(resting_pose(spec, xy, s * turn, on_side))
    return poses


def axis_error_deg(X_est: np.ndarray, X_true: np.ndarray, axis: int = 2) -> float:
    """Angle between one body axis in the two poses: the rotation error of an object that is
    symmetric about that axis (a cylinder's roll about its own axis is unobservable)."""
    c = float(X_est[:3, axis] @ X_true[:3, axis])
    return float(np.rad2deg(np.arccos(np.clip(c, -1.0, 1.0))))


def track_sequence(harness: PerceptionHarness, poses: list[RigidTransform],
                   symmetry_axis: int | None = None) -> dict:
    """Tracks a kinematic sequence; per-frame errors against the true pose.

    With `symmetry_axis`, rotation_error_deg is the angle between that body axis in the true
    and estimated poses; the full rotation error is kept as full_rotation_error_deg.
    """
    harness.set_object(poses[0])
    harness.reset_tracker()
    errors, ok, axis = [], [], []
    for X in poses:
        harness.set_object(X)
        state = harness.track()
        errors.append(pose_error(state.X, X.GetAsMatrix4()))
        if symmetry_axis is not None:
            axis.append(axis_error_deg(state.X, X.GetAsMatrix4(), symmetry_axis))
        ok.append(state.status[0])
    e = np.asarray(errors)
    rot = np.asarray(axis) if symmetry_axis is not None else e[:, 1]
    return {"translation_error_m": e[:, 0], "rotation_error_deg": rot,
            "full_rotation_error_deg": e[:, 1], "ok": np.asarray(ok)}
