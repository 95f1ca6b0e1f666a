"""Typed configs for the student rollout diagram (base: diagrams/student_rollout.yaml).

The teacher part is the teacher's own TeacherDiagramConfig; cameras, segmentation, tracker and
the student's observation noise are added here. Every default is the value the student diagram
runs with; diagrams/student_rollout.yaml names only what the student changes in the teacher's
settings. `StudentDiagramConfig.check()` raises an InputError naming the field for a value the
diagram cannot run with (the loader and the diagram builder call it).
No `from __future__ import annotations`: yaml_load_typed needs real types on the fields.
"""


import dataclasses as dc
import math

from pydrake.systems.sensors import CameraConfig

from corn_drake.config.plumbing.bounds import check_bounds, one_of, relation
from corn_drake.config.choices import CAMERA_MODES, SEGMENTATION_MODES  # noqa: F401 (re-exported)
from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.config.plumbing.yaml_io import pickle_as_yaml
from corn_drake.contract import ENCODER_INPUT_SCALE
from corn_drake.errors import InputError

# The authors' three eyes (official code), in the table frame = our world frame.
DEFAULT_EYES = [[0.458, -0.40, 0.740], [-0.238, 0.388, 0.694], [-0.408, -0.328, 0.706]]

OUTLIER_SCALINGS = ("pixel_density", "none")

# CameraConfig fields the rig cannot honour, and why. They must keep Drake's defaults, so a value
# set there is refused instead of silently ignored.
UNUSED_CAMERA_FIELDS = {
    "X_PB": "each camera's pose comes from cameras.eyes and look_at (or the aim, in tracking mode)",
    "X_BC": "the color and depth sensors sit at the camera body (the clouds use its pose)",
    "X_BD": "the color and depth sensors sit at the camera body (the clouds use its pose)",
    "fps": "images are rendered when the segmentation asks, once per policy step",
    "capture_offset": "images are rendered when the segmentation asks, once per policy step",
    "output_delay": "images are rendered when the segmentation asks, once per policy step",
    "do_compress": "nothing is published over LCM",
    "lcm_bus": "nothing is published over LCM",
}


def default_camera() -> CameraConfig:
    """One camera's settings, shared by every eye of the rig (Drake's own camera config)."""
    return CameraConfig(
        # 128 x 96 runs the whole chain well above 30 Hz here (corn-drake bench perception).
        width=128, height=96,
        # Fixed mode: 50 deg vertical field of view covers the 0.4 x 0.5 m table from every eye.
        focal=CameraConfig.FovDegrees(y=50.0),
        clipping_near=0.01, clipping_far=2.0, z_near=0.01, z_far=2.0,
        renderer_name="perception_vtk", renderer_class="RenderEngineVtk",
        # System names camera0, camera1, ...; the chain reads depth (and the label image in
        # ground-truth segmentation); nothing reads color.
        name="camera", rgb=False, depth=True, label=True)


# A student config travels to Ray workers like the teacher's.
pickle_as_yaml(CameraConfig)


def _check_point(name: str, value) -> None:
    if len(value) != 3 or not all(math.isfinite(v) for v in value):
        raise InputError(f"{name} must be 3 finite numbers (x, y, z in metres), got {value}")


def _same_value(a, b) -> bool:
    from pydrake.common.schema import Transform

    if isinstance(a, Transform):  # Transform has no ==
        return (a.base_frame == b.base_frame and a.IsDeterministic()
                and a.GetDeterministicValue().IsExactlyEqualTo(b.GetDeterministicValue()))
    return a == b


def check_camera(camera: CameraConfig, name: str = "cameras.camera") -> None:
    """InputError naming the field for a CameraConfig the rig cannot render with."""
    drake_defaults = CameraConfig()
    for field, why in UNUSED_CAMERA_FIELDS.items():
        if not _same_value(getattr(camera, field), getattr(drake_defaults, field)):
            raise InputError(f"{name}.{field} is not used by the camera rig ({why}); leave it "
                             f"at Drake's default")
    if not camera.depth:
        raise InputError(f"{name}.depth must be true: the perception chain reads depth images")
    if not camera.name:
        raise InputError(f"{name}.name must not be empty (it names the camera systems)")
    if not (camera.renderer_class in ("", "RenderEngineVtk")
            or type(camera.renderer_class).__name__ == "RenderEngineVtkParams"):
        raise InputError(f"{name}.renderer_class: the camera rig renders with RenderEngineVtk "
                         f"('', 'RenderEngineVtk' or !RenderEngineVtkParams), got "
                         f"{camera.renderer_class!r}")
    try:
        camera.MakeCameras()  # Drake's own checks: sizes, focal, centre, ranges
    except RuntimeError as e:
        raise InputError(f"invalid {name}: {' '.join(str(e).split())}") from None


@dc.dataclass
class CameraRigConfig:
    # "fixed": sensors welded to the world looking at look_at; "tracking": re-aimed at the
    # object every time SceneGraph evaluates poses (the paper's student cameras, 32 x 32 each).
    mode: str = "fixed"
    eyes: list[list[float]] = dc.field(default_factory=lambda: [list(e) for e in DEFAULT_EYES])
    look_at: list[float] = dc.field(default_factory=lambda: [0.0, 0.0, 0.45])
    # Drake's CameraConfig: size, focal (used in fixed mode), clipping and depth ranges,
    # renderer. Pixels with no return (beyond z_far, nearer than z_near) are dropped downstream.
    camera: CameraConfig = dc.field(default_factory=default_camera)
    # Tracking mode: the focal is computed for fov = 2 atan(margin * object radius / eye
    # distance), set once at construction (camera.focal is not used then).
    tracking_fov_margin: float = 1.3
    # Keep the robot out of the images (not what a real camera sees, but what the paper's
    # renderer did: it rasterised the object only). Off by default: our links are primitives
    # (cheap to render) and the segmentation is supposed to remove them.
    hide_robot: bool = False
    # Range checks (config/plumbing/bounds.py): what check_bounds refuses. Of Drake's CameraConfig the
    # rig relies on its image size and its clipping and depth ranges (check_camera has Drake's
    # own checks of the rest, and refuses the fields the rig ignores).
    # Sizes have upper bounds (issue 63: an unbounded size ran out of memory after the config
    # was written): a 4096-pixel-wide image per camera.
    BOUNDS = {"tracking_fov_margin": "> 0", "mode": one_of(CAMERA_MODES),
              "eyes": "list vector 3 finite", "look_at": "vector 3 finite",
              "camera.width": "[1, 4096]", "camera.height": "[1, 4096]", "camera.clipping_near": "> 0",
              "camera.clipping_far": "> 0", "camera.z_near": "> 0", "camera.z_far": "> 0"}
    # A camera at the point it looks at has no viewing direction (its pose is undefined).
    RELATIONS = (relation("eyes", "away from {look_at} (each camera looks from its eye to it)",
                          lambda eyes, at: all(math.dist(e, at) > 1e-6 for e in eyes),
                          "look_at"),)

    def check(self) -> None:
        check_bounds(self, "cameras.")
        if self.mode not in CAMERA_MODES:
            raise InputError(f"cameras.mode must be one of {', '.join(CAMERA_MODES)}, "
                             f"got {self.mode!r}")
        if not self.eyes:
            raise InputError("cameras.eyes is empty: give at least one camera position")
        for i, eye in enumerate(self.eyes):
            _check_point(f"cameras.eyes[{i}]", eye)
        _check_point("cameras.look_at", self.look_at)
        check_camera(self.camera)


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
    # Radius outlier removal: a point stays with at least n neighbours within outlier_radius.
    # outlier_neighbours is the paper's n = 96, for a D435 at 640 x 480, i.e. at
    # outlier_reference_px_per_m (about 560 px/m at 0.6 m). outlier_scaling "pixel_density"
    # scales n by (this rig's px/m / reference)^2 (the ratio of points a patch of surface
    # gets), never below 2: the default 128 x 96 rig has 174 px/m, n = 9. "none" uses
    # outlier_neighbours as it is (0 or 1 keeps every point).
    outlier_radius: float = 0.02
    outlier_scaling: str = "pixel_density"
    outlier_neighbours: int = 96
    outlier_reference_px_per_m: float = 560.0
    # DBSCAN on what is left; the largest cluster is the object. eps is at least
    # dbscan_min_eps_pixels pixel footprints (1 / px_per_m): with coarse images an eps below
    # the point spacing splits every face into clusters (default rig: 2.5 / 174 = 14 mm).
    dbscan_eps: float = 0.01
    dbscan_min_eps_pixels: float = 2.5
    dbscan_min_points: int = 4
    # Above this pixel density (rows per metre at the eye distance) the points left after the
    # crop / table / robot stages are voxel-thinned to 1 / max_px_per_m (4 mm) first, and n and
    # eps are set for that density: a 640 x 480 rig took 1 s per frame without it.
    max_px_per_m: float = 250.0
    seed: int = 0
    # Range checks (config/plumbing/bounds.py): what check_bounds refuses. outlier_neighbours is a count
    # (0 or 1 keeps every point).
    # Sizes have upper bounds (issue 63: an unbounded size ran out of memory after the config
    # was written): 65536 points a cloud, 128x the policy's 512.
    BOUNDS = {"num_points": "[1, 65536]", "crop_height": "> 0", "outlier_radius": "> 0",
              "outlier_reference_px_per_m": "> 0", "outlier_neighbours": ">= 0",
              "dbscan_eps": "> 0", "dbscan_min_eps_pixels": ">= 0", "dbscan_min_points": ">= 1",
              "max_px_per_m": "> 0", "mode": one_of(SEGMENTATION_MODES),
              "crop_margin_xy": ">= 0", "table_margin": ">= 0", "robot_margin": ">= 0",
              "outlier_scaling": one_of(OUTLIER_SCALINGS), "seed": "seed"}

    def check(self) -> None:
        check_bounds(self, "segmentation.")
        if self.mode not in SEGMENTATION_MODES:
            raise InputError(f"segmentation.mode must be one of {', '.join(SEGMENTATION_MODES)}, "
                             f"got {self.mode!r}")
        if self.outlier_scaling not in OUTLIER_SCALINGS:
            raise InputError(f"segmentation.outlier_scaling must be one of "
                             f"{', '.join(OUTLIER_SCALINGS)}, got {self.outlier_scaling!r}")


@dc.dataclass
class TrackerConfig:
    # The tracker updates once per policy step, at the PolicyClock's perception offset
    # (time_step / 4): after the last plant update of each policy step and before the policy's
    # latch reads the estimate, so the estimate for step k comes from the cloud of the state the
    # policy acts on (corn_drake.timing; no setting here).
    max_points: int = 2048
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
    # Range checks (config/plumbing/bounds.py): what check_bounds refuses. The fitnesses are fractions of
    # points.
    # Sizes have upper bounds (issue 63: an unbounded size ran out of memory after the config
    # was written): 65536 points a cloud, 128x the policy's 512.
    BOUNDS = {"max_points": "[1, 65536]", "normal_radius": "> 0", "max_correspondence": "> 0",
              "max_iterations": ">= 1", "reregister_fitness": "[0, 1]",
              "reregister_correspondence": "> 0", "min_fitness": "[0, 1]",
              "max_step_translation": "> 0", "max_step_rotation_deg": "> 0", "min_points": ">= 1"}

    def check(self) -> None:
        check_bounds(self, "tracker.")


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
    # Range checks (config/plumbing/bounds.py): standard deviations (m).
    BOUNDS = {"cloud_noise_std": ">= 0", "goal_noise_std": ">= 0"}


@dc.dataclass
class StudentDiagramConfig:
    teacher: TeacherDiagramConfig = dc.field(default_factory=TeacherDiagramConfig)
    cameras: CameraRigConfig = dc.field(default_factory=CameraRigConfig)
    segmentation: SegmentationConfig = dc.field(default_factory=SegmentationConfig)
    tracker: TrackerConfig = dc.field(default_factory=TrackerConfig)
    observation: StudentObservationConfig = dc.field(default_factory=StudentObservationConfig)

    def check(self) -> None:
        """InputError naming the first field the student diagram cannot be built with."""
        self.teacher.check()  # the scene, task and randomization under the cameras
        check_bounds(self.observation, "observation.")
        self.cameras.check()
        self.segmentation.check()
        self.tracker.check()
        if self.segmentation.mode == "ground_truth" and not self.cameras.camera.label:
            raise InputError("cameras.camera.label must be true for segmentation.mode "
                             "ground_truth (it reads the label images)")
