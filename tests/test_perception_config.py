"""The student diagram's config: the base YAML names only what differs from the defaults, layers
load on top of a base, Drake's CameraConfig travels through YAML and pickle, and every value the
diagram cannot run with is an InputError naming its field. No rendering needed."""

import copy
import pickle

import pytest
import yaml
from pydrake.common.yaml import yaml_dump_typed
from pydrake.systems.sensors import CameraConfig

from corn_drake.config.plumbing.loader import load_config
from corn_drake.config.student import StudentDiagramConfig
from corn_drake.config.plumbing.diagram_files import STUDENT_BASE_DIAGRAM, load_student_config
from corn_drake.errors import InputError
from corn_drake.systems.perception.segmentation import dbscan_eps, outlier_points


class _TaggedLoader(yaml.SafeLoader):
    """Reads Drake's variant tags (focal: !FovDegrees {...}) as a `!` key beside the fields."""


_TaggedLoader.add_multi_constructor(
    "!", lambda loader, tag, node: {"!": tag, **loader.construct_mapping(node, deep=True)})


def _flat(cfg) -> dict:
    def walk(value, prefix):
        if not isinstance(value, dict):
            return {prefix: value}
        out = {}
        for k, v in value.items():
            out.update(walk(v, f"{prefix}.{k}" if prefix else k))
        return out

    return walk(yaml.load(yaml_dump_typed(cfg), Loader=_TaggedLoader), "")


def _differences(a, b) -> dict:
    fa, fb = _flat(a), _flat(b)
    return {k: (fa.get(k), fb.get(k)) for k in fa.keys() | fb.keys() if fa.get(k) != fb.get(k)}


def test_base_yaml_names_only_the_students_torque_noise():
    """The base diagram differs from the dataclass defaults in exactly the key it names."""
    assert _differences(load_student_config(), StudentDiagramConfig()) == {
        "teacher.randomization.torque_noise_std": (0.03, 0.0)}
    text = STUDENT_BASE_DIAGRAM.read_text()
    data = yaml.safe_load(text)
    assert data == {"teacher": {"randomization": {"torque_noise_std": 0.03}}}


def test_a_layer_loads_on_top_of_its_base_and_leaves_the_base_alone(tmp_path):
    base = load_student_config()
    base.cameras.camera.width = 64
    overlay = tmp_path / "overlay.yaml"
    overlay.write_text("segmentation: {mode: ground_truth}\ncameras: {camera: {height: 40}}\n")
    cfg = load_student_config(overlay, base=base)
    # The layer's keys, the base's changes (including the base diagram's torque noise) and
    # Drake's CameraConfig merged field by field.
    assert cfg.segmentation.mode == "ground_truth"
    assert (cfg.cameras.camera.width, cfg.cameras.camera.height) == (64, 40)
    assert cfg.teacher.randomization.torque_noise_std == 0.03
    assert cfg.cameras.camera.focal.y == 50.0
    assert base.segmentation.mode == "geometric" and base.cameras.camera.height == 96
    # Without a base the same layer sits on the dataclass defaults.
    plain = load_student_config(overlay)
    assert plain.cameras.camera.width == 128 and plain.teacher.randomization.torque_noise_std == 0


def test_loader_names_the_file_and_the_field(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("segmentation: {outlier_min_point: 5}\n")
    with pytest.raises(InputError, match="bad.yaml.*outlier_min_point"):
        load_student_config(bad)
    # The old field: its -1 meant "scale it", a count meant a fixed count; the count now scales
    # by default, so the old name is refused rather than silently reinterpreted.
    bad.write_text("segmentation: {outlier_min_points: 30}\n")
    with pytest.raises(InputError, match="outlier_min_points"):
        load_student_config(bad)
    with pytest.raises(InputError, match="not found"):
        load_student_config(tmp_path / "missing.yaml")
    # A bad value in a file holding one of Drake's variant tags is still an InputError.
    bad.write_text("cameras:\n  camera:\n    focal: !FovDegrees {y: 30}\n    width: wide\n")
    with pytest.raises(InputError, match="bad.yaml.*wide"):
        load_student_config(bad)


def test_resolved_config_round_trips_through_yaml_and_pickle():
    cfg = load_student_config()
    cfg.cameras.mode = "tracking"
    cfg.cameras.camera.width = 32
    cfg.cameras.camera.focal = CameraConfig.FocalLength(x=40.0, y=41.0)
    # The text a run's config.yaml would hold loads back to the same config, and passes check.
    again = load_config(StudentDiagramConfig, text=yaml_dump_typed(cfg))
    again.check()
    assert _differences(again, cfg) == {}
    # Ray ships configs to workers by pickle; Drake's CameraConfig travels as its YAML.
    unpickled = pickle.loads(pickle.dumps(cfg))
    assert _differences(unpickled, cfg) == {}
    assert unpickled.cameras.camera.focal.x == 40.0


def _bad(edit):
    cfg = StudentDiagramConfig()
    edit(cfg)
    return cfg


@pytest.mark.parametrize("edit, field", [
    (lambda c: setattr(c.cameras.camera, "renderer_class", "RenderEngineGl"),
     "cameras.camera.renderer_class"),
    (lambda c: setattr(c.cameras, "mode", "orbiting"), "cameras.mode"),
    (lambda c: setattr(c.cameras, "eyes", []), "cameras.eyes"),
    (lambda c: setattr(c.cameras, "eyes", [[0.4, 0.4]]), r"cameras.eyes must be .*3 finite"),
    (lambda c: setattr(c.cameras, "look_at", [0.0, float("nan"), 0.4]), "cameras.look_at"),
    (lambda c: setattr(c.cameras, "tracking_fov_margin", 0.0), "cameras.tracking_fov_margin"),
    (lambda c: setattr(c.cameras.camera, "width", 0), "cameras.camera.width must be"),
    (lambda c: setattr(c.cameras.camera, "z_far", 3.0), "cameras.camera.*depth range"),
    (lambda c: setattr(c.cameras.camera, "depth", False), "cameras.camera.depth"),
    (lambda c: setattr(c.cameras.camera, "fps", 30.0), "cameras.camera.fps"),
    (lambda c: setattr(c.cameras.camera, "lcm_bus", "robot"), "cameras.camera.lcm_bus"),
    (lambda c: setattr(c.cameras.camera, "X_PB", _moved_transform()), "cameras.camera.X_PB"),
    (lambda c: (setattr(c.segmentation, "mode", "ground_truth"),
                setattr(c.cameras.camera, "label", False)), "cameras.camera.label"),
    (lambda c: setattr(c.segmentation, "mode", "labels"), "segmentation.mode"),
    (lambda c: setattr(c.segmentation, "outlier_scaling", "auto"), "segmentation.outlier_scaling"),
    (lambda c: setattr(c.segmentation, "outlier_neighbours", -1), "segmentation.outlier_neighbours"),
    (lambda c: setattr(c.segmentation, "outlier_radius", 0.0), "segmentation.outlier_radius"),
    (lambda c: setattr(c.segmentation, "num_points", 0), "segmentation.num_points"),
    (lambda c: setattr(c.tracker, "reregister_fitness", 1.5), "tracker.reregister_fitness"),
    (lambda c: setattr(c.tracker, "max_correspondence", -0.02), "tracker.max_correspondence"),
])
def test_values_the_diagram_cannot_run_with_name_their_field(edit, field):
    with pytest.raises(InputError, match=field):
        _bad(edit).check()


def _moved_transform():
    from pydrake.common.schema import Transform

    X = Transform()
    X.translation = [0.0, 0.0, 1.0]
    return X


def test_defaults_pass_the_check():
    StudentDiagramConfig().check()
    tracking = StudentDiagramConfig()
    tracking.cameras.mode = "tracking"
    tracking.check()


def test_outlier_count_scales_with_pixel_density_or_is_taken_as_given():
    seg = StudentDiagramConfig().segmentation
    assert seg.outlier_scaling == "pixel_density" and seg.outlier_neighbours == 96
    # At the paper's D435 density n is the paper's 96; at the default rig's 174 px/m it is
    # 96 * (174 / 560)^2 = 9.3 -> 9; never below 2.
    assert outlier_points(seg, seg.outlier_reference_px_per_m) == 96
    assert outlier_points(seg, 174.18) == 9
    assert outlier_points(seg, 10.0) == 2
    fixed = copy.deepcopy(seg)
    fixed.outlier_scaling, fixed.outlier_neighbours = "none", 30
    assert outlier_points(fixed, 174.18) == outlier_points(fixed, 560.0) == 30
    fixed.outlier_scaling = "auto"
    with pytest.raises(InputError, match="outlier_scaling"):
        outlier_points(fixed, 174.18)


def test_dbscan_eps_grows_to_the_pixel_footprint():
    seg = StudentDiagramConfig().segmentation
    assert dbscan_eps(seg, 174.18) == pytest.approx(2.5 / 174.18)
    assert dbscan_eps(seg, 1000.0) == seg.dbscan_eps  # fine images: the configured 1 cm
    seg.dbscan_min_eps_pixels = 0.0
    assert dbscan_eps(seg, 174.18) == seg.dbscan_eps
