"""`corn-drake demo` end to end at its default size (a few minutes): every stage's output is
there and holds what that stage should have written, not just a file."""

import json
import math
from pathlib import Path

import pytest
import torch

from corn_drake.cli import build_parser, main
from corn_drake.commands.demo import SHIPPED_TEACHER, TASK
from corn_drake.package_data import data_dir
from tests.recordings import attention_in_recording
from corn_drake.run_folders.config_file import load_run_config

pytestmark = pytest.mark.slow


def _non_finite(value, where="") -> list[str]:
    """Paths of the NaN/inf numbers anywhere in a parsed JSON value."""
    if isinstance(value, float):
        return [] if math.isfinite(value) else [where]
    if isinstance(value, dict):
        return [p for k, v in value.items() for p in _non_finite(v, f"{where}/{k}")]
    if isinstance(value, list):
        return [p for i, v in enumerate(value) for p in _non_finite(v, f"{where}[{i}]")]
    return []


def _report(path: Path) -> dict:
    data = json.loads(path.read_text())
    assert not _non_finite(data), (path.name, _non_finite(data))
    return data


def _is_meshcat_html(path: Path) -> bool:
    text = path.read_text(errors="replace")
    return path.stat().st_size > 10_000 and "<html" in text.lower() and "meshcat" in text.lower()


def test_demo_runs_and_writes_its_outputs(tmp_path):
    argv = ["demo", "--out", str(tmp_path), "--bench-steps", "20"]
    args = build_parser().parse_args(argv)  # the demo's defaults: what the outputs must reflect
    assert main(argv) == 0

    objects = json.loads((tmp_path / "library" / "manifest.json").read_text())["objects"]
    assert len(objects) == args.num_objects
    unseen = {o["id"] for o in objects if o["split"] == "unseen"}
    assert unseen and len(unseen) < len(objects)

    pretraining = _report(tmp_path / "pretrain" / "corn" / "metrics.json")
    assert pretraining["steps"] == args.pretrain_steps
    assert 0.0 <= pretraining["unseen_patch_accuracy"] <= 1.0
    assert (tmp_path / "pretrain" / "corn" / "encoder.pt").stat().st_size > 100_000

    run = tmp_path / "teacher_corn"
    metrics = _report(run / "metrics.json")
    cfg = load_run_config(run)
    per_update = cfg.envs_per_worker * max(cfg.workers, 1) * cfg.rollout_steps
    # Whole updates until the requested steps are reached.
    updates = -(-args.train_steps // per_update)
    assert cfg.total_steps == args.train_steps and cfg.policy == "corn" and cfg.env.task.name == TASK
    assert metrics["updates"] == len(metrics["history"]) == updates
    assert [h["step"] for h in metrics["history"]] == [per_update * (i + 1) for i in range(updates)]
    assert metrics["global_step"] == per_update * updates
    checkpoint = torch.load(run / "checkpoints" / "last.pt", weights_only=False)
    assert checkpoint["global_step"] == metrics["global_step"] and checkpoint["policy"] == "corn"
    assert (run / "plots" / "learning_curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    evaluation = _report(tmp_path / "eval_corn.json")
    assert evaluation["split"] == "unseen" and len(evaluation["episodes"]) == args.eval_episodes
    # Evaluated on the task the run was trained on, read from its config.yaml.
    assert evaluation["task"] == cfg.env.task.name
    assert evaluation["action_step"] == cfg.env.controller.max_position_delta
    assert set(evaluation["per_object"]) <= unseen
    assert 0.0 <= evaluation["success_rate"] <= 1.0
    assert all(e["position_error"] >= 0.0 and e["steps"] > 0 for e in evaluation["episodes"])
    recordings = list((tmp_path / "eval_corn_recordings").glob("*.html"))
    assert recordings and all(_is_meshcat_html(p) for p in recordings)

    # The shipped teacher, on its own task (push), with its attention in the recording.
    shipped = _report(tmp_path / "eval_shipped_corn.json")
    card = json.loads((data_dir("models") / "weights" / SHIPPED_TEACHER / "card.json").read_text())
    assert shipped["policy"] == card["policy"] == "corn" and shipped["task"] == card["task"]
    assert len(shipped["episodes"]) == args.eval_episodes
    assert set(shipped["per_object"]) <= unseen
    shipped_recordings = list((tmp_path / "eval_shipped_corn_recordings").glob("*.html"))
    assert shipped_recordings and all(_is_meshcat_html(p) for p in shipped_recordings)
    objects, tracks = attention_in_recording(shipped_recordings[0].read_text())
    assert objects and tracks  # one attention cloud per step, each shown at its step

    assert _is_meshcat_html(tmp_path / "scripted_push.html")
    sim = _report(tmp_path / "bench_sim.json")["results"]
    assert sim["policy_steps_per_s"] > 0 and sim["bare_physics_policy_steps_per_s"] > 0
