"""Tracking a slid and turned object through the whole chain (render -> segment -> ICP), and the
`bench tracking` / `bench perception` reports."""

import json

import numpy as np
import pytest

from corn_drake.systems.perception.cameras import rendering_available

ok, reason = rendering_available()
pytestmark = pytest.mark.skipif(not ok, reason=reason)


def test_a_slid_and_turned_object_is_tracked_within_1cm_and_5deg():
    from corn_drake.builders.perception_harness import (PerceptionHarness, slide_and_turn_poses,
                                                        track_sequence)
    from corn_drake.scene.objects import box_spec

    spec = box_spec([0.12, 0.06, 0.03], 0.3)
    h = PerceptionHarness(spec=spec)
    # A quicker push than the benchmark's (same path in 4 s): larger steps per frame.
    r = track_sequence(h, slide_and_turn_poses(spec, duration=4.0))
    assert np.median(r["translation_error_m"]) <= 0.01
    assert np.median(r["rotation_error_deg"]) <= 5.0
    assert r["translation_error_m"].max() < 0.02 and r["ok"].all()


def test_bench_tracking_report(tmp_path):
    from corn_drake.cli import main

    out = tmp_path / "tracking.json"
    assert main(["bench", "tracking", "--report", str(out), "--duration", "1.5",
                 "--objects", "box_90x70x50", "cylinder_on_side_r30_l120"]) == 0
    res = json.loads(out.read_text())["results"]
    assert set(res["per_object"]) == {"box_90x70x50", "cylinder_on_side_r30_l120"}
    for key in ("median_translation_error_m", "median_rotation_error_deg", "per_object"):
        assert key in res
    assert res["median_translation_error_m"] <= 0.01 and res["median_rotation_error_deg"] <= 5


def test_bench_perception_report(tmp_path):
    from corn_drake.cli import main

    out = tmp_path / "perception.json"
    assert main(["bench", "perception", "--report", str(out), "--frames", "10"]) == 0
    res = json.loads(out.read_text())["results"]
    assert res["frames_per_s"] > 0 and res["frames"] == 10
    assert set(res["stage_ms"]) == {"render", "depth_to_cloud", "segmentation", "tracking"}
