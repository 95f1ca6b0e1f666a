"""`corn-drake demo` end to end at a small size (its default size takes 6-10 minutes; what it
printed there is in docs/results/demo/): every stage's output is there and holds what that
stage should have written, not just a file, and the three evaluations it compares ran the same
episodes."""

import json
import math
from pathlib import Path

import pytest
import torch

from corn_drake.cli import build_parser, main
from corn_drake.commands.demo import LOG_EVERY, SHIPPED_POLICY, TASK, untrained_agent
from corn_drake.package_data import data_dir
from corn_drake.config.plumbing.loader import load_config
from corn_drake.config.primitive import PrimitiveTrainConfig
from corn_drake.run_folders.config_file import run_config_path

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


def _episodes(report: dict) -> list[tuple]:
    return [(e["object"], e["seed"]) for e in report["episodes"]]


def test_demo_runs_and_writes_its_outputs(tmp_path):
    # The smallest library with both splits (2 train, 1 unseen: demo refuses fewer) and two
    # evaluation episodes: every stage still runs and writes what it writes at full size.
    argv = ["demo", "--out", str(tmp_path), "--num-objects", "3", "--num-samples", "4000",
            "--pretrain-steps", "40", "--train-steps", "400", "--eval-episodes", "2",
            "--encoder", "pretrain"]  # every stage, however busy the machine is
    args = build_parser().parse_args(argv)
    assert main(argv) == 0

    objects = json.loads((tmp_path / "library" / "manifest.json").read_text())["objects"]
    assert len(objects) == args.num_objects
    unseen = {o["id"] for o in objects if o["split"] == "unseen"}
    assert unseen and len(unseen) < len(objects)

    pretraining = _report(tmp_path / "pretrain" / "corn" / "metrics.json")
    assert pretraining["steps"] == args.pretrain_steps
    assert 0.0 <= pretraining["unseen_patch_auroc"] <= 1.0
    encoder_file = tmp_path / "pretrain" / "corn" / "encoder.pt"
    assert encoder_file.stat().st_size > 100_000

    run = tmp_path / "policy"
    metrics = _report(run / "metrics.json")
    cfg = load_config(PrimitiveTrainConfig, run_config_path(run))
    assert cfg.policy == "primitive" and cfg.env.task.name == TASK
    assert cfg.total_steps == args.train_steps and metrics["global_step"] >= args.train_steps
    # A row every LOG_EVERY primitives (a round of 8 envs may pass the mark by a few).
    assert [h["step"] // LOG_EVERY for h in metrics["history"]] == list(
        range(1, metrics["global_step"] // LOG_EVERY + 1))
    checkpoint = torch.load(run / "checkpoints" / "last.pt", weights_only=False)
    assert checkpoint["global_step"] == metrics["global_step"]
    assert (run / "encoder.pt").read_bytes() == encoder_file.read_bytes()
    assert (run / "plots" / "learning_curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    reports = {name: _report(tmp_path / f"eval_{name}.json")
               for name in ("untrained", "trained", "shipped")}
    episodes = _episodes(reports["untrained"])
    assert len(episodes) == args.eval_episodes and {o for o, _ in episodes} <= unseen
    for name, report in reports.items():
        # The same objects and goals for the three: the comparison the demo prints.
        assert _episodes(report) == episodes, name
        assert report["task"] == TASK and report["split"] == "unseen"
        rows = report["episodes"]
        assert report["success_rate"] == pytest.approx(sum(e["success"] for e in rows) / len(rows))
    shipped_card = json.loads((data_dir("models") / "weights" / SHIPPED_POLICY / "card.json")
                              .read_text())
    assert shipped_card["task"] == TASK
    recordings = list((tmp_path / "eval_trained_recordings").glob("*.html"))
    assert len(recordings) == 1 and _is_meshcat_html(recordings[0])

    summary = _report(tmp_path / "demo_summary.json")
    assert summary["success"] == {name: r["success_rate"] for name, r in reports.items()}
    assert summary["train_primitives"] == metrics["global_step"]
    assert summary["curve"] == [{"primitives": h["step"], "success_rate": h["success_rate"]}
                                for h in metrics["history"]]
    assert set(summary["unseen_objects"]) == unseen

    # A rerun of the same command resumes: the library, encoder and trained policy are found,
    # not made again; other arguments that define them are refused, naming them.
    hulls = sorted((tmp_path / "library").glob("*/hull_*.obj"))
    made = {p: p.stat().st_mtime_ns for p in hulls}
    assert main(argv) == 0
    assert {p: p.stat().st_mtime_ns for p in made} == made  # no object built again
    resumed = _report(tmp_path / "pretrain" / "corn" / "metrics.json")
    assert (resumed["steps"], resumed["train_seconds"]) == (  # no pretraining step again
        pretraining["steps"], pretraining["train_seconds"])
    again = torch.load(run / "checkpoints" / "last.pt", weights_only=False)
    assert again["global_step"] == checkpoint["global_step"]  # no primitive trained again
    assert main([*argv[:-4], "--eval-episodes", "2", "--num-objects", "4"]) == 2


def test_the_untrained_policy_is_the_one_training_starts_from(tmp_path):
    """The demo's "untrained" evaluation is of the weights PrimitiveTrainer starts from: built
    the same way, they must be equal tensor for tensor (a trainer change that reorders its
    seeding would make the demo compare against another policy)."""
    from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
    from corn_drake.rl.pretrained_encoders import load_encoder
    from corn_drake.rl.training.primitive_trainer import PrimitiveTrainer

    encoder = data_dir("models") / "weights" / "push_corn" / "encoder.pt"
    cfg = PrimitiveTrainConfig(env=load_primitive_env_config(TASK), envs_per_worker=1, seed=7)
    trainer = PrimitiveTrainer(cfg, tmp_path, load_encoder("corn", encoder))
    def weights(agent) -> dict:
        state = agent.network_state()
        return {f"{part}.{name}": t for part in ("actor", "critic") for name, t in state[part].items()}

    started, demo = weights(trainer.agent), weights(untrained_agent(cfg, encoder))
    assert started and started.keys() == demo.keys()
    assert all(torch.equal(started[k], demo[k]) for k in started)
    # And the seed matters: another seed's untrained agent differs.
    other = weights(untrained_agent(PrimitiveTrainConfig(env=cfg.env, seed=8), encoder))
    assert any(not torch.equal(started[k], other[k]) for k in started)


def test_the_budget_takes_the_shipped_encoder_only_where_pretraining_would_not_fit(tmp_path,
                                                                                  capsys,
                                                                                  monkeypatch):
    """`--encoder auto` decides from the probes' times (given here: no timing in a test): at
    400 pretraining steps and 1,200 primitives a quiet project core pretrains, one running the
    demo's work 2.5x slower takes the shipped encoder and says so; at the default sizes even a
    quiet core takes it (all five stages took 12.4 minutes there); a rerun keeps the first
    choice, and an --encoder that contradicts it is refused, naming both."""
    from argparse import Namespace

    from corn_drake.commands import demo, demo_budget
    from corn_drake.errors import InputError

    quiet = dict(demo_budget.REFERENCE_PROBE_S)
    busy = {k: 2.5 * v for k, v in quiet.items()}
    sizes = {**demo_budget.DEFAULT_SIZES, "pretraining": 400, "training": 1200}
    assert demo_budget.plan(sizes, "auto", quiet)[0] is False
    assert demo_budget.plan(dict(demo_budget.DEFAULT_SIZES), "auto", quiet)[0] is True
    shipped, expected, slowdowns = demo_budget.plan(sizes, "auto", busy)
    assert shipped and slowdowns == pytest.approx({"torch": 2.5, "python": 2.5})
    assert sum(expected.values()) > demo_budget.BUDGET_S
    assert demo_budget.plan(sizes, "pretrain", busy)[0] is False
    assert demo_budget.plan(sizes, "shipped", quiet)[0] is True

    args = Namespace(encoder="auto", **{f"{k}": v for k, v in (
        ("num_objects", 14), ("num_samples", 20_000), ("pretrain_steps", 600),
        ("train_steps", 2400), ("eval_episodes", 20))})
    monkeypatch.setattr(demo_budget, "pace_probe", lambda: busy)
    assert demo._budget(args, tmp_path) is True
    said = capsys.readouterr().out
    assert "shipped CORN encoder" in said and "would not fit" in said
    monkeypatch.setattr(demo_budget, "pace_probe", lambda: quiet)
    assert demo._budget(args, tmp_path) is True  # the first run's choice holds on a rerun
    with pytest.raises(InputError, match="--encoder pretrain.*shipped"):
        demo._budget(Namespace(**{**vars(args), "encoder": "pretrain"}), tmp_path)
