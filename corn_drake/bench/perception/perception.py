"""`corn-drake bench perception --report FILE.json`: frames/s of the whole perception chain.

One frame = render 3 depth cameras -> 3 world-frame clouds -> segmentation (geometric: crop,
table, robot links, outliers, DBSCAN) -> one ICP tracker update, on a slide-and-turn pose
sequence of the default box with the arm in view, at the configured (default) resolution. The
per-stage mean times come from evaluating the stages one after the other (Drake caches each
output, so each stage's time excludes the stages before it). Goal: >= 30 frames/s.
"""

from __future__ import annotations

import time

from corn_drake.arguments.value_types import positive_int
from corn_drake.config.choices import CAMERA_MODES, SEGMENTATION_MODES

NAME = "perception"
HELP = "frames/s of render -> cloud -> segmentation -> ICP pose, with a per-stage breakdown"


def add_arguments(parser):
    parser.add_argument("--config", default=None, help="student diagram YAML, read on top of "
                        "the defaults like diagrams/student_rollout.yaml (the default)")
    parser.add_argument("--frames", type=positive_int, default=100, help="frames timed")
    parser.add_argument("--width", type=positive_int, default=None,
                        help="camera width in pixels (default: the config's)")
    parser.add_argument("--height", type=positive_int, default=None,
                        help="camera height in pixels (default: the config's)")
    parser.add_argument("--mode", choices=CAMERA_MODES, default=None,
                        help="camera mode (default: the config's)")
    parser.add_argument("--segmentation", choices=SEGMENTATION_MODES, default=None,
                        help="segmentation (default: the config's)")


def measure(cfg, frames: int = 100, progress: bool = True) -> dict:
    import numpy as np
    from tqdm import tqdm

    from corn_drake.builders.perception_harness import PerceptionHarness, slide_and_turn_poses

    harness = PerceptionHarness(cfg)
    spec = harness.scene.object_spec
    period = harness.frame_period
    poses = slide_and_turn_poses(spec, duration=frames * period, period=period)
    harness.set_object(poses[0])
    harness.reset_tracker()
    harness.track()  # first frame: renderer warm-up and tracker initialization
    stages, counts = [], []
    t0 = time.perf_counter()
    for X in tqdm(poses[1:frames + 1], desc="perception", disable=not progress):
        harness.set_object(X)
        stages.append(harness.stage_times())
        counts.append(harness.segmented_cloud().shape[0])
    wall = time.perf_counter() - t0
    mean = {k: float(np.mean([s[k] for s in stages])) for k in stages[0]}
    total = sum(mean.values())
    return {
        "frames_per_s": len(stages) / wall,
        "chain_ms_per_frame": 1e3 * total,
        "stage_ms": {k: 1e3 * v for k, v in mean.items()},
        "stage_fraction": {k: v / total for k, v in mean.items()},
        "frames": len(stages),
        "resolution": [cfg.cameras.camera.width, cfg.cameras.camera.height],
        "camera_mode": cfg.cameras.mode,
        "segmentation_mode": cfg.segmentation.mode,
        "segmented_points_mean": float(np.mean(counts)),
        "goal_frames_per_s": 30.0,
    }


def run(args) -> dict:
    from corn_drake.config.plumbing.diagram_files import load_student_config

    cfg = load_student_config(args.config)
    camera = cfg.cameras.camera
    if args.width:
        camera.width = args.width
    if args.height:
        camera.height = args.height
    if args.mode:
        cfg.cameras.mode = args.mode
        if args.mode == "tracking" and not (args.width or args.height):
            camera.width = camera.height = 32  # the paper's per-camera size
    if args.segmentation:
        cfg.segmentation.mode = args.segmentation
    result = measure(cfg, args.frames)
    # Same-run baseline: rendering alone at the same resolution (the floor of the chain).
    result["baseline_render_only_frames_per_s"] = 1e3 / result["stage_ms"]["render"]
    return result
