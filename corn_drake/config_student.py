"""Typed configs for the student rollout diagram (diagrams/student_rollout.yaml).

The teacher part is the teacher's own TeacherDiagramConfig; cameras, segmentation, tracker and
the student's observation noise are added here. No `from __future__ import annotations`:
yaml_load_typed needs real types on the fields.
"""


import dataclasses as dc

from corn_drake.config import TeacherDiagramConfig
from corn_drake.contract import ENCODER_INPUT_SCALE

# The authors' three eyes (official code), in the table frame = our world frame.
DEFAULT_EYES = [[0.458, -0.40, 0.740], [-0.238, 0.388, 0.694], [-0.408, -0.328, 0.706]]


@dc.dataclass
class CameraRigConfig:
    # "fixed": sensors welded to the world looking at look_at; "tracking": re-aimed at the
    # object every time SceneGraph evaluates poses (the paper's student cameras).
    mode: str = "fixed"
    eyes: list[list[float]] = dc.field(default_factory=lambda: [list(e) for e in DEFAULT_EYES])
    look_at: list[float] = dc.field(default_factory=lambda: [0.0, 0.0, 0.45])
    # 128 x 96 runs the whole chain well above 30 Hz here (corn-drake bench perception).
    width: int = 128
    height: int = 96
    # Fixed mode: vertical field of view. 50 deg covers the 0.4 x 0.5 m table from every eye.
    fov_y_deg: float = 50.0
    # Tracking mode: fov = 2 atan(margin * object radius / eye distance), set once.
    tracking_fov_margin: float = 1.3
    z_near: float = 0.01
    z_far: float = 2.0
    # Keep the robot out of the images (not what a real camera sees, but what the paper's
    # renderer did: it rasterised the object only). Off by default: our links are primitives
    # (cheap to render) and the segmentation is supposed to remove them.
    hide_robot: bool = False


@dc.dataclass
class SegmentationConfig:
    # "geometric": the real-world chain (crop, table, robot links, outliers, DBSCAN);
    # "ground_truth": the renderer's label image (fast, for training).
    mode: str = "geometric"
    num_points: int = 512
    # Workspace crop: the table's xy extent grown by this margin, z from the table top up to
    # table top + crop_height.
    crop_margin_xy: float = 0.05
    crop_height: float = 0.4
    # Drop points within this height of the table top. The paper used 1 cm against D435 noise;
    # rendered depth is exact (table points at 0.4 +- 3e-8 m), and the band is lost object
    # too: 1 cm cost 11-12 % of a 5 cm box's points, 5 mm 6 %, 3 mm 3-4 %
    # (tests/test_perception_segmentation.py needs >= 95 % recall). Use 0.01 on real depth.
    table_margin: float = 0.003
    # Robot link primitives are grown by this much before the inside test. Our rendered links
    # are exactly these primitives, so 5 mm suffices in simulation (1 cm cost 10 % of an
    # object pressed against the finger pads); grow it for a real robot's calibration error.
    robot_margin: float = 0.005
    # Radius outlier removal: at least n neighbours within r. The paper's n = 96 is for a
    # D435 at 640 x 480 (about 560 px/m at 0.6 m); n < 0 scales it with this rig's pixel
    # density (pixels per metre at the eye distance, squared), never below 2.
    outlier_radius: float = 0.02
    outlier_min_points: int = -1
    outlier_reference_points: int = 96
    outlier_reference_px_per_m: float = 560.0
    # DBSCAN on what is left; the largest cluster is the object. eps grows to 2.5x the pixel
    # footprint when the images are coarse (eps below the point spacing splits every face).
    dbscan_eps: float = 0.01
    # Above this pixel density (rows per metre at the eye distance) the points left after the
    # crop / table / robot stages are voxel-thinned to 1 / max_px_per_m (4 mm) first, and n and
    # eps are set for that density: a 640 x 480 rig took 1 s per frame without it.
    max_px_per_m: float = 250.0
    dbscan_min_points: int = 4
    seed: int = 0


@dc.dataclass
class TrackerConfig:
    period: float = 0.1  # one estimate per policy step
    # Offset of the periodic update; < 0 means the PolicyClock's perception offset (time_step / 4):
    # after the last plant update of each policy step and before the policy's latch reads the
    # estimate, so the estimate for step k comes from the cloud of the state the policy acts on.
    offset: float = -1.0
    max_points: int = 2048
    voxel_size: float = 0.0  # > 0: downsample clouds before ICP
    normal_radius: float = 0.02
    max_correspondence: float = 0.02  # frame to frame, m
    max_iterations: int = 30
    # Re-registration against the first frame is accepted above this fitness (paper: 0.6).
    reregister_fitness: float = 0.6
    reregister_correspondence: float = 0.01
    # A frame-to-frame result below this fitness, or above these jumps, is not trusted: the
    # tracker keeps its last pose and reports low confidence.
    min_fitness: float = 0.3
    max_step_translation: float = 0.05
    max_step_rotation_deg: float = 30.0
    min_points: int = 20


# The encoders' input normalisation divides positions by this (contract.ENCODER_INPUT_SCALE):
# the paper's observation noises are stated in those units.
NORMALISED_UNIT_M = ENCODER_INPUT_SCALE


@dc.dataclass
class StudentObservationConfig:
    # Std of N(0, s) per cloud coordinate, in metres: the paper's N(0, 0.005) on the normalised
    # cloud (its Table "Range for domain randomization"; the authors' PerturbCloud adds it after
    # normalisation), i.e. 0.005 x 0.4 m = 2 mm.
    cloud_noise_std: float = 0.005 * NORMALISED_UNIT_M
    # Std of N(0, s) on the goal's position (its first 3 entries), in metres: the paper's
    # N(0, 0.005) goal-pose noise on the normalised input, 2 mm. (The authors' code sets 0.)
    goal_noise_std: float = 0.005 * NORMALISED_UNIT_M


@dc.dataclass
class StudentDiagramConfig:
    teacher: TeacherDiagramConfig = dc.field(default_factory=TeacherDiagramConfig)
    cameras: CameraRigConfig = dc.field(default_factory=CameraRigConfig)
    segmentation: SegmentationConfig = dc.field(default_factory=SegmentationConfig)
    tracker: TrackerConfig = dc.field(default_factory=TrackerConfig)
    observation: StudentObservationConfig = dc.field(default_factory=StudentObservationConfig)
