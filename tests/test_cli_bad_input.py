"""Bad input to every subcommand: a non-zero exit, exactly one line on stderr naming the argument
or file, no traceback, and nothing written or changed. Every row fails before any simulation or
training starts (validation comes before the work), so the table runs in seconds in-process."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from corn_drake.cli import _command_modules, main
from corn_drake.commands import bench
from tests.fixtures import write_tiny_library
from tests.paths import REPO_ROOT

REPO = Path(__file__).resolve().parents[1]

# Object-library manifests that are broken in the ways a user meets: a binary file, an emptied
# one, valid JSON of the wrong shape, an entry without its id.
BROKEN_MANIFESTS = {
    "lib_garbage": b"\xff\xfe\x00\x13\x8a garbage",
    "lib_empty": b"",
    "lib_no_objects": json.dumps({"rejected": []}).encode(),
    "lib_no_id": json.dumps({"objects": [{"split": "train", "cloud": "c.npy", "radius": 0.1}]}).encode(),
}
BAD_TYPE_YAML = "task:\n  episode_steps: lots\n"
# Item 14's other faces: each broken config is named with its field where it has one.
BROKEN_CONFIGS = {
    "bad_list.yaml": (b"scene:\n  object:\n    size: 3\n", "scene.object.size"),
    "scalar_section.yaml": (b"task: 5\n", "field task"),
    "bad_syntax.yaml": (b"task: [1, 2\n", "not valid YAML"),
    "binary.yaml": (b"\xff\xfe\x00\x13", "not a UTF-8 text file"),
    "unknown_key.yaml": (b"task:\n  episode_stepz: 3\n", "episode_stepz"),
}


def _row(argv: str, *names: str):
    """One table row: the command line ({root} is the fixture folder) and what the error names."""
    return pytest.param(argv.split(), names, id=argv.replace("{root}/", ""))


OUT = "--out {root}/out"
REPORT = "--report {root}/out/report.json"
# A shipped primitive run, to reach what is checked after a run loads.
SHIPPED_PRIMITIVE = str(REPO_ROOT / "models" / "weights" / "push_primitive")
BENCH_REPORT = "--report {root}/out/bench.json"

ROWS = [
    # no command, an unknown one
    _row("", "COMMAND"),
    _row("nosuch", "nosuch"),
    # objects (issue 18 items 6, 9, 12)
    _row(f"objects --num-objects 0 {OUT}", "--num-objects"),
    _row(f"objects --num-objects -3 {OUT}", "--num-objects"),
    _row(f"objects --num-objects many {OUT}", "--num-objects"),
    _row(f"objects --drops 0 {OUT}", "--drops"),
    _row(f"objects --seed -1 {OUT}", "--seed"),
    _row("objects --num-objects 2", "--out"),
    # Ownership (issue 63): a folder holding what the command did not make is refused, named.
    _row("objects --num-objects 2 --out {root}/run_no_history", "{root}/run_no_history",
         "metrics.json", "did not make"),
    _row(f"contact-data --objects {{root}}/lib --num-samples 8 --out {{root}}/lib",
         "{root}/lib", "manifest.json", "did not make"),
    _row("demo --out {root}/run_no_history", "{root}/run_no_history", "metrics.json",
         "`corn-drake demo` did not make"),
    _row("objects --source {root}/empty_meshes --out {root}/new_lib", "{root}/empty_meshes"),
    _row("objects --source {root}/nowhere --out {root}/new_lib", "{root}/nowhere"),
    # contact-data (items 4, 12, 15)
    _row(f"contact-data --objects {{root}}/lib --num-samples -5 {OUT}", "--num-samples"),
    _row(f"contact-data --objects {{root}}/lib --num-samples 0 {OUT}", "--num-samples"),
    _row(f"contact-data --objects {{root}}/lib --num-samples 8 --shard-size 0 {OUT}", "--shard-size"),
    _row(f"contact-data --objects {{root}}/lib --num-samples 8 --eval-samples 0 {OUT}", "--eval-samples"),
    _row(f"contact-data --objects {{root}}/lib --num-samples 8 --seed -2 {OUT}", "--seed"),
    _row(f"contact-data --objects {{root}}/nowhere --num-samples 8 {OUT}", "{root}/nowhere"),
    # pretrain (item 7)
    _row(f"pretrain --data {{root}}/nowhere --steps 0 {OUT}", "--steps"),
    _row(f"pretrain --data {{root}}/nowhere --batch-size 0 {OUT}", "--batch-size"),
    _row(f"pretrain --data {{root}}/nowhere --eval-every 0 {OUT}", "--eval-every"),
    _row(f"pretrain --data {{root}}/nowhere --pointnet-steps 0 {OUT}", "--pointnet-steps"),
    _row(f"pretrain --data {{root}}/nowhere --lr 0 {OUT}", "--lr"),
    _row(f"pretrain --data {{root}}/nowhere --lr nan {OUT}", "--lr"),
    _row(f"pretrain --data {{root}}/nowhere {OUT}", "{root}/nowhere"),
    # train (items 9, 14, 15)
    _row(f"train --steps 0 {OUT}", "--steps"),
    _row(f"train --resume {OUT}", "--resume", "no run to resume"),
    _row(f"train --steps -5 {OUT}", "--steps"),
    _row(f"train --envs-per-worker 0 {OUT}", "--envs-per-worker"),
    _row(f"train --rollout-steps 0 {OUT}", "--rollout-steps"),
    _row(f"train --workers -1 {OUT}", "--workers"),
    _row(f"train --minibatches 0 {OUT}", "--minibatches"),
    # More minibatches than a rollout's transitions (issue 63: cut to one each without a word).
    _row(f"train --rollout-steps 4 --envs-per-worker 2 --minibatches 9 {OUT}", "--minibatches",
         "rollout_steps (4) x envs_per_worker (2)"),
    _row(f"train --rollout-steps 4 --envs-per-worker 2 --set ppo.minibatches=9 {OUT}",
         "ppo.minibatches", "rollout's transitions", "got 9"),
    _row(f"train --init-log-std nan {OUT}", "--init-log-std"),
    # A Ray address nothing answers at: one line at once, not ray.init retrying for minutes.
    _row("train --policy state --workers 1 --ray-address 127.0.0.1:1 --out {root}/new_run",
         "--ray-address",
         "127.0.0.1:1"),
    # A cluster address with no Ray worker to send there (issue 63: accepted, ran locally).
    _row("train --policy state --ray-address 127.0.0.1:1 --out {root}/new_run", "--ray-address",
         "--workers N"),
    _row("train --policy primitive --ray-address 127.0.0.1:1 --out {root}/new_run",
         "--ray-address", "--workers N"),
    _row(f"train --torch-threads 0 {OUT}", "--torch-threads"),
    _row(f"train --torch-threads some {OUT}", "--torch-threads", "'torch', 'auto' or an integer"),
    _row(f"train --policy bogus {OUT}", "--policy"),
    _row(f"train --set ppo.lrr=1 {OUT}", "--set ppo.lrr=1", "ppo.lrr"),
    _row(f"train --set task.episode_stepz=3 {OUT}", "task.episode_stepz"),
    _row(f"train --set task.episode_steps=lots {OUT}", "--set task.episode_steps=lots",
         "env.task.episode_steps"),
    _row(f"train --set ppo.epochs=1.5 {OUT}", "--set ppo.epochs=1.5", "epochs"),
    _row(f"train --set seed {OUT}", "--set seed", "KEY=VALUE"),
    _row(f"train --set snapshot_every=-1 {OUT}", "--set snapshot_every", ">= 0"),
    _row(f"train --init-from {{root}}/nowhere {OUT}", "--init-from {root}/nowhere"),
    _row(f"train --set seed=[1 {OUT}", "--set seed=[1", "YAML"),
    _row(f"train --task nosuch_task {OUT}", "--task nosuch_task", "no such task"),
    _row(f"train --task {{root}}/bad_type.yaml {OUT}", "{root}/bad_type.yaml", "task.episode_steps"),
    _row(f"train --task {{root}}/nowhere.yaml {OUT}", "{root}/nowhere.yaml"),
    _row(f"train --objects {{root}}/nowhere {OUT}", "{root}/nowhere"),
    # evaluate (items 8, 14)
    _row(f"evaluate --run scripted --episodes 0 {REPORT}", "--episodes"),
    _row(f"evaluate --run scripted --checkpoint step_000000064.pt {REPORT}", "--checkpoint",
         "kept checkpoints", "reference controller"),
    _row(f"evaluate --run scripted --record -1 {REPORT}", "--record"),
    _row(f"evaluate --run scripted --torch-threads 1.5 {REPORT}", "--torch-threads"),
    _row(f"evaluate --run scripted --seed -1 {REPORT}", "--seed"),
    _row(f"evaluate --run scripted --stochastic {REPORT}", "--stochastic"),
    _row(f"evaluate --run scripted --perception geometric {REPORT}", "--perception geometric"),
    _row(f"evaluate --run scripted --perception oracle {REPORT}", "--perception"),
    _row(f"evaluate --run scripted --attention {REPORT}", "--attention", "reference"),
    _row(f"evaluate --run {{root}}/nowhere {REPORT}", "{root}/nowhere/config.yaml"),
    _row(f"evaluate --run scripted --task {{root}}/bad_type.yaml {REPORT}",
         "{root}/bad_type.yaml", "task.episode_steps"),
    _row(f"evaluate --run scripted --task nosuch_task {REPORT}", "--task nosuch_task"),
    _row(f"evaluate --run scripted --set task.episode_stepz=3 {REPORT}", "task.episode_stepz"),
    # evaluate runs a policy on an env: training settings are no override of it
    _row(f"evaluate --run scripted --set ppo.lr=1e-4 {REPORT}", "--set ppo.lr=1e-4", "env"),
    # the tiny library holds clouds only: evaluate needs each object's full scene description
    _row(f"evaluate --run scripted --objects {{root}}/lib --split all {REPORT}",
         "{root}/lib/manifest.json", "unit_inertia"),
    # bench primitive
    _row(f"bench primitive {BENCH_REPORT} --decisions 0", "--decisions"),
    _row(f"bench primitive {BENCH_REPORT} --task {{root}}/bad_type.yaml", "{root}/bad_type.yaml"),
    _row(f"bench primitive {BENCH_REPORT} --encoder {{root}}/nowhere.pt", "{root}/nowhere.pt"),
    # bench policies
    _row(f"bench policies --policies bogus {BENCH_REPORT}", "--policies"),
    _row(f"bench policies --policies corn,corn {BENCH_REPORT}", "--policies"),
    _row(f"bench policies --objects {{root}}/nowhere {BENCH_REPORT}", "{root}/nowhere"),
    _row(f"curves --run {{root}}/nowhere --rates {{root}}/nowhere.json --out {{root}}/out/c.png",
         "{root}/nowhere.json"),
    # compare
    _row("compare", "--report"),
    _row("compare --report {root}/nowhere.json", "{root}/nowhere.json"),
    _row("compare --report {root}/bad_type.yaml", "{root}/bad_type.yaml"),
    # curves
    _row("curves --run {root}/nowhere --out {root}/out/c.png", "{root}/nowhere"),
    # ship / gallery (shipped weights, issue 17) and objects --split
    _row("ship --run {root}/run_no_history --report {root}/nowhere.json --library-command x "
         "--out {root}/out/w", "--report", "{root}/nowhere.json"),
    _row("ship --run {root}/run_no_history --report {root}/lib_garbage/manifest.json "
         "--library-command x --out {root}/out/w", "--report"),
    _row("ship --run {root}/run_no_history --report {root}/lib_no_objects/manifest.json "
         "--library-command x --out {root}/out/w", "--report", "success_rate"),
    _row("gallery --run {root}/nowhere --objects {root}/lib --out {root}/out/g",
         "{root}/nowhere/config.yaml"),
    _row("gallery --run scripted --objects {root}/lib --out {root}/out/g", "scripted/config.yaml"),
    _row(f"gallery --run {SHIPPED_PRIMITIVE} --objects {{root}}/lib --set primitive.bogus=1 "
         "--out {root}/out/g", "primitive.bogus"),
    _row(f"objects --source {{root}}/lib --split unseen {OUT}", "--split unseen", "--source"),
    _row("curves --run {root}/run_garbage_metrics --out {root}/out/c.png",
         "{root}/run_garbage_metrics/metrics.json"),
    _row("curves --run {root}/run_no_history --out {root}/out/c.png", "{root}/run_no_history/metrics.json"),
    _row("curves --run {root}/run_no_history", "--out"),
    # bench
    _row("bench", "WHAT"),
    _row("bench sim --steps 10", "--report"),
    _row(f"bench sim {BENCH_REPORT} --steps 0", "--steps"),
    _row(f"bench sim {BENCH_REPORT} --envs-per-worker 0", "--envs-per-worker"),
    _row(f"bench sim {BENCH_REPORT} --workers 0", "--workers"),
    _row(f"bench sim {BENCH_REPORT} --task {{root}}/bad_type.yaml", "{root}/bad_type.yaml"),
    _row(f"bench sim {BENCH_REPORT} --baseline-physics {{root}}/nowhere.yaml",
         "{root}/nowhere.yaml"),
    _row(f"bench sim {BENCH_REPORT} --baseline-physics {{root}}/bad_type.yaml",
         "{root}/bad_type.yaml"),
    _row(f"bench learner {BENCH_REPORT} --batches 0,64", "--batches"),
    _row(f"bench learner {BENCH_REPORT} --policy nosuch", "--policy"),
    _row(f"bench planner {BENCH_REPORT} --set planner.beam=0", "planner.beam"),
    _row(f"bench planner {BENCH_REPORT} --set planner.policy=runs/none", "planner.policy"),
    _row(f"bench train {BENCH_REPORT} --envs-per-worker 0", "--envs-per-worker"),
    _row(f"bench train {BENCH_REPORT} --updates 0", "--updates"),
    _row(f"bench train {BENCH_REPORT} --warmup-updates -1", "--warmup-updates"),
    _row(f"bench train {BENCH_REPORT} --rollout-steps 0", "--rollout-steps"),
    _row(f"bench train {BENCH_REPORT} --bare-steps 0", "--bare-steps"),
    _row(f"bench train {BENCH_REPORT} --seed -1", "--seed"),
    _row(f"bench train {BENCH_REPORT} --torch-threads 0", "--torch-threads"),
    _row(f"bench policies {BENCH_REPORT} --torch-threads -2", "--torch-threads"),
    _row(f"bench policies {BENCH_REPORT} --set task.episode_steps=5", "--set task.episode_steps=5",
         "only ppo.* settings"),
    _row(f"bench policies {BENCH_REPORT} --set ppo.nosuch=1", "--set ppo.nosuch=1"),
    _row(f"bench train {BENCH_REPORT} --policy bogus", "--policy"),
    _row(f"bench train {BENCH_REPORT} --task nosuch_task", "--task nosuch_task", "no such task"),
    _row(f"bench train {BENCH_REPORT} --task {{root}}/bad_type.yaml", "{root}/bad_type.yaml",
         "task.episode_steps"),
    _row(f"bench cores {BENCH_REPORT} --procs 0", "--procs"),
    _row(f"bench cores {BENCH_REPORT} --procs 1,1", "--procs", "1 more than once"),
    _row(f"bench cores {BENCH_REPORT} --envs-per-worker 0", "--envs-per-worker"),
    _row(f"bench cores {BENCH_REPORT} --segments 0", "--segments"),
    _row(f"bench cores {BENCH_REPORT} --task nosuch_task", "--task nosuch_task", "no such task"),
    _row(f"bench scale {BENCH_REPORT} --workers 0", "--workers"),
    _row(f"bench scale {BENCH_REPORT} --workers 1,x", "--workers"),
    _row(f"bench scale {BENCH_REPORT} --workers=", "--workers"),
    _row(f"bench scale {BENCH_REPORT} --workers 1,2,2", "--workers", "2 more than once"),
    _row(f"bench scale {BENCH_REPORT} --envs-per-worker 0", "--envs-per-worker"),
    _row(f"bench scale {BENCH_REPORT} --updates 0", "--updates"),
    _row(f"bench scale {BENCH_REPORT} --device gpu", "--device 'gpu'"),
    _row(f"bench scale {BENCH_REPORT} --task nosuch_task", "--task nosuch_task", "no such task"),
    _row(f"bench contact-data {BENCH_REPORT} --samples 0", "--samples"),
    _row(f"bench contact-data {BENCH_REPORT} --batch -1", "--batch"),
    _row(f"bench contact-data {BENCH_REPORT} --objects {{root}}/lib_no_id", "{root}/lib_no_id/manifest.json"),
    _row(f"bench encoder {BENCH_REPORT} --batches 1,x", "--batches"),
    _row(f"bench encoder {BENCH_REPORT} --batches 64,0", "--batches"),
    _row(f"bench perception {BENCH_REPORT} --frames 0", "--frames"),
    _row(f"bench perception {BENCH_REPORT} --width 0", "--width"),
    _row(f"bench tracking {BENCH_REPORT} --duration 0", "--duration"),
    _row(f"bench tracking {BENCH_REPORT} --objects nosuch_box", "nosuch_box"),
    _row(f"bench student {BENCH_REPORT} --steps 0", "--steps"),
    _row(f"bench student {BENCH_REPORT} --repeats 0", "--repeats"),
    _row(f"bench student {BENCH_REPORT} --perception oracle", "--perception"),
    _row(f"bench student {BENCH_REPORT} --config {{root}}/bad_type.yaml", "{root}/bad_type.yaml"),
    # demo
    _row("demo --out {root}/demo --num-objects 0", "--num-objects"),
    # A library with no unseen object: refused before its first stage builds anything (issue
    # 63: built a library, contact data and an encoder first).
    _row("demo --out {root}/demo --num-objects 2", "--num-objects 2", "0 unseen",
         "--num-objects 3"),
    _row("demo --out {root}/demo --num-samples 0", "--num-samples"),
    _row("demo --out {root}/demo --pretrain-steps 0", "--pretrain-steps"),
    _row("demo --out {root}/demo --train-steps -1", "--train-steps"),
    _row("demo --out {root}/demo --eval-episodes 0", "--eval-episodes"),
    _row("demo --out {root}/demo --bench-steps 0", "--bench-steps"),
    _row("demo --out {root}/demo --seed -1", "--seed"),
]

# The learner's device: a malformed one (a device the machine lacks: tests/test_bench_scale.py).
# The outcome model's data and fit (issue 52): the proposing run is a shipped one.
PROPOSER = str(Path(__file__).resolve().parents[1] / "models" / "weights" / "push_turn_primitive")
ROWS += [
    _row(f"collect-outcomes {PROPOSER} --objects {{root}}/nosuch --episodes 1 {OUT}/c",
         "{root}/nosuch"),
    _row(f"collect-outcomes {PROPOSER} --objects {{root}}/lib --episodes 0 {OUT}/c",
         "--episodes"),
    _row(f"collect-outcomes {{root}}/nosuch_run --objects {{root}}/lib --episodes 1 {OUT}/c",
         "nosuch_run"),
    _row(f"fit-outcome {PROPOSER} --data {{root}}/nosuch --out-run {{root}}/out/fit",
         "--data", "{root}/nosuch"),
    _row(f"fit-outcome {PROPOSER} --data {{root}}/lib --seed -1 --out-run {{root}}/out/fit",
         "--seed"),
    _row(f"fit-outcome {PROPOSER} --data {{root}}/lib --out-run {{root}}/out", "{root}/out"),
]
# Relations and sizes (issue 63): a run too short to update, sizes past what memory holds.
ROWS += [
    _row("train --policy primitive --steps 100 --out {root}/out/p", "total_steps",
         "learning_starts"),
    _row("train --policy primitive --set primitive.push_distance=1e300 --out {root}/out/p",
         "primitive.push_distance", "(0, 0.5]"),
    _row("train --policy primitive --set replay_capacity=1000000000000 --out {root}/out/p",
         "replay_capacity"),
    _row("train --envs-per-worker 100000 --out {root}/out/t", "envs_per_worker"),
    _row(f"train --policy primitive --init-from {REPO}/models/weights/push_corn --steps 600 "
         "--out {root}/out/p", "--init-from", "a dense PPO teacher run"),
]
# The expert's labels and the chooser fitted to them (issue 61).
ROWS += [
    _row("label --objects {root}/nosuch --out {root}/out/l", "--objects {root}/nosuch"),
    _row("label --objects {root}/lib --out {root}/out/l.json", "--out {root}/out/l.json"),
    _row("label --objects {root}/lib --episodes 0 --out {root}/out/l", "--episodes"),
    _row("label --objects {root}/lib --ray-address 127.0.0.1:1 --out {root}/out/l",
         "--ray-address needs --workers"),
    _row("evaluate --run still --workers 2 --report {root}/out/r.json",
         "--workers 2 applies to the 6D expert", "--run still is a reference controller"),
    _row("fit-chooser --labels {root}/nosuch --objects {root}/lib --out-run {root}/out/f",
         "--labels {root}/nosuch"),
    _row("fit-chooser --labels {root}/lib --objects {root}/lib --out-run {root}/out/f",
         "--labels {root}/lib", "labels.jsonl"),
    _row("fit-chooser --labels {root}/lib --objects {root}/lib --held-out 1 --out-run "
         "{root}/out/f", "--held-out 1"),
    _row("fit-chooser --labels {root}/lib --objects {root}/lib --out-run {root}/out",
         "--out-run {root}/out"),
]
# A planner evaluation's split parts merged (issue 54).
ROWS += [
    _row("merge-reports {root}/nosuch.rows.jsonl --report {root}/out/m.json", "nosuch.rows.jsonl"),
    _row("merge-reports {root}/out/report.json --report {root}/out/m.json", "not an evaluation's rows file"),
    _row("merge-reports {root}/lib/manifest.json", "--report"),
]
ROWS += [_row(f"train --device gpu {OUT}", "--device: device must be cpu, cpu:N, cuda or cuda:N, got 'gpu'")]

ROWS += [_row(f"train --task {{root}}/{name} {OUT}", "{root}/" + name, detail)
         for name, (_, detail) in BROKEN_CONFIGS.items()]

# distill (issue 15): the teacher run must exist and be a trained teacher run.
ROWS += [_row(f"distill {OUT}", "--run"),
         _row(f"distill --run {{root}}/nosuch {OUT}", "--run {root}/nosuch"),
         _row(f"distill --run {{root}}/run_no_history {OUT}",
              "--run {root}/run_no_history", "not a trained teacher run"),
         _row(f"distill --run {{root}}/nosuch --steps 0 {OUT}", "--steps"),
         _row(f"distill --run {{root}}/nosuch --perception magic {OUT}", "--perception"),
         _row(f"distill --run {{root}}/nosuch --torch-threads 0 {OUT}", "--torch-threads")]

# Issue 55: one spelling per concept; the old one is refused, naming the new one.
ROWS += [_row(f"objects --num 2 {OUT}", "--num is now --num-objects"),
         _row("demo --out {root}/demo --contact-samples 5", "--contact-samples is now --num-samples"),
         _row(f"distill --teacher {{root}}/nosuch {OUT}", "--teacher is now --run"),
         # a mistyped flag, command, choice or --set key: the closest one is named
         _row(f"train --stpes 5 {OUT}", "--stpes", "did you mean --steps?"),
         _row(f"objects --num-object 2 --drosp 3 {OUT}", "--drosp", "did you mean --drops?"),
         _row("trian", "'trian'", "did you mean train?"),
         _row(f"train --policy cron {OUT}", "did you mean corn?"),
         _row(f"bench sim {BENCH_REPORT} --repets 2", "did you mean --repeats?"),
         _row(f"train --set ppo.lrr=1 {OUT}", "did you mean 'ppo.lr'?"),
         _row(f"train --set task.episode_stepz=3 {OUT}", "did you mean 'task.episode_steps'?"),
         _row(f"evaluate --run scripted --set task.goal_xx=[0,1] {REPORT}",
              "did you mean 'task.goal_x'?")]

# Item 12: every command that reads an object library names the broken manifest.
LIBRARY_READERS = ["objects --num-objects 1 --out LIB", f"contact-data --objects LIB --num-samples 8 {OUT}",
                   f"train --objects LIB {OUT}", f"evaluate --run scripted --objects LIB {REPORT}"]
ROWS += [_row(argv.replace("LIB", "{root}/" + lib), "{root}/" + lib + "/manifest.json")
         for argv in LIBRARY_READERS for lib in BROKEN_MANIFESTS]


@pytest.fixture(scope="module")
def root(tmp_path_factory) -> Path:
    """Inputs for the rows, plus pre-existing outputs that a failed command must leave alone."""
    root = tmp_path_factory.mktemp("bad_input")
    write_tiny_library(root / "lib")
    for name, content in BROKEN_MANIFESTS.items():
        (root / name).mkdir()
        (root / name / "manifest.json").write_bytes(content)
    (root / "empty_meshes").mkdir()
    (root / "bad_type.yaml").write_text(BAD_TYPE_YAML)
    for name, (content, _) in BROKEN_CONFIGS.items():
        (root / name).write_bytes(content)
    (root / "run_garbage_metrics").mkdir()
    (root / "run_garbage_metrics" / "metrics.json").write_text('{"history": [')
    (root / "run_no_history").mkdir()
    (root / "run_no_history" / "metrics.json").write_text('{"global_step": 64}')
    (root / "out").mkdir()
    for name in ("report.json", "bench.json", "c.png", "metrics.json"):
        (root / "out" / name).write_text(f"previous {name}\n")
    return root


def snapshot(root: Path) -> dict[str, str]:
    """Every file and folder under `root`, files by content hash."""
    return {str(p.relative_to(root)): "dir" if p.is_dir() else hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*"))}


def prog_of(argv: list[str]) -> str:
    """`corn-drake [COMMAND [BENCHMARK]]`: who the error line says failed."""
    words = ["corn-drake"]
    if argv and argv[0] in {m.NAME for m in _command_modules()}:
        words.append(argv[0])
        if argv[0] == "bench" and len(argv) > 1 and argv[1] in {m.NAME for m in bench._bench_modules()}:
            words.append(argv[1])
    return " ".join(words)


def run_cli(argv: list[str]) -> int:
    try:
        return main(argv)
    except SystemExit as e:  # argparse's errors exit
        return e.code


@pytest.mark.parametrize("argv, names", ROWS)
def test_bad_input_is_one_line_naming_it(root, capsys, monkeypatch, argv, names):
    monkeypatch.delenv("CORN_DRAKE_DEBUG", raising=False)
    argv = [a.format(root=root) for a in argv]
    before = snapshot(root)
    code = run_cli(argv)
    err = capsys.readouterr().err
    assert code not in (0, None), f"exit {code} for {argv}"
    assert "Traceback" not in err
    assert len(err.splitlines()) == 1, f"expected one line on stderr, got:\n{err}"
    assert err.startswith(f"{prog_of(argv)}: error: "), err
    for name in names:
        assert name.format(root=root) in err, f"{name!r} not named in: {err}"
    assert snapshot(root) == before, "a failed command changed or wrote files"


def test_every_subcommand_has_rows():
    """A new subcommand (or benchmark) must come with its bad-input rows."""
    commands = {m.NAME for m in _command_modules()}
    benches = {m.NAME for m in bench._bench_modules()}
    covered = {p.values[0][0] for p in ROWS if p.values[0]}
    covered_benches = {p.values[0][1] for p in ROWS if p.values[0][:1] == ["bench"] and len(p.values[0]) > 1}
    assert commands <= covered, f"no rows for {sorted(commands - covered)}"
    assert benches <= covered_benches, f"no rows for bench {sorted(benches - covered_benches)}"


def test_debug_flag_keeps_the_traceback(root, monkeypatch):
    from corn_drake.errors import InputError

    monkeypatch.delenv("CORN_DRAKE_DEBUG", raising=False)
    with pytest.raises(InputError, match="lib_garbage"):
        main(["--debug", "contact-data", "--objects", str(root / "lib_garbage"), "--num-samples", "8",
              "--out", str(root / "out")])


def test_the_installed_entry_point_behaves_the_same(root):
    """The real process: exit status 2 and one line, for an argparse error and an input error."""
    paths = [str(REPO), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}  # this checkout's code, not another
    env.pop("CORN_DRAKE_DEBUG", None)
    before = snapshot(root)
    for argv, name in ((["train", "--steps", "0", "--out", str(root / "out")], "--steps"),
                       (["contact-data", "--objects", str(root / "lib_garbage"), "--num-samples", "8",
                         "--out", str(root / "out")], str(root / "lib_garbage" / "manifest.json"))):
        proc = subprocess.run([sys.executable, "-m", "corn_drake.cli", *argv], env=env, cwd=root,
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2, proc.stderr
        assert len(proc.stderr.splitlines()) == 1 and name in proc.stderr, proc.stderr
    assert snapshot(root) == before


def test_library_object_files_are_named(tmp_path):
    """An object whose manifest entry is complete but whose arrays are gone or corrupt."""
    from corn_drake.assets.library import SPEC_FIELDS, load_object_spec
    from corn_drake.errors import InputError

    entry = {"id": "box", "split": "train", "mass": 0.2, "radius": 0.05, "thin": False, "hulls": [],
             "visual": "box.obj", **{k: f"box_{k}.npy" for k in ("unit_inertia", "cloud",
                                                                    "stable_poses", "bbox_corners")}}
    assert set(entry) >= set(SPEC_FIELDS)
    (tmp_path / "manifest.json").write_text(json.dumps({"objects": [entry]}))
    with pytest.raises(FileNotFoundError, match="box_unit_inertia.npy") as missing:
        load_object_spec(tmp_path, "box")
    assert isinstance(missing.value, InputError)
    (tmp_path / "box_unit_inertia.npy").write_bytes(b"not an array")
    with pytest.raises(InputError, match="box_unit_inertia.npy"):
        load_object_spec(tmp_path, "box")
    with pytest.raises(InputError, match="'nosuch' not in library"):
        load_object_spec(tmp_path, "nosuch")


def test_garbage_encoder_checkpoint_is_named(tmp_path):
    from corn_drake.errors import InputError
    from corn_drake.nn.encoders.encoder_files import load_frozen_encoder

    bad = tmp_path / "enc.pt"
    bad.write_bytes(b"\x80\x02garbage that is no pickle")
    with pytest.raises(InputError, match="enc.pt"):
        load_frozen_encoder(bad)


def test_ingest_resumes_a_manifest_without_bookkeeping_keys(tmp_path):
    """A hand-written manifest may hold only "objects"; ingesting more must not KeyError."""
    from corn_drake.assets.library import ingest_folder

    source, out = tmp_path / "meshes", tmp_path / "lib"
    source.mkdir()
    out.mkdir()
    (source / "broken.obj").write_text("this is no mesh\n")
    (out / "manifest.json").write_text(json.dumps({"objects": []}))
    manifest = ingest_folder(source, out, progress=False)
    assert [r.source for r in manifest.rejected] == ["broken.obj"]
    on_disk = json.loads((out / "manifest.json").read_text())["rejected"]
    assert on_disk == [{"source": r.source, "reason": r.reason} for r in manifest.rejected]


@pytest.mark.parametrize("setting, names", [
    ("task.goal_x=[0.2,0.1]", ("task.goal_x",)),
    ("randomization.object_radius=[0,0]", ("randomization.object_radius",)),
])
def test_train_refuses_a_task_no_episode_can_come_from_before_writing(tmp_path, capsys, setting,
                                                                     names):
    """A range no episode can be drawn from is refused before the run's config is written: a
    written one could never be resumed with the corrected value."""
    out = tmp_path / "run"
    assert main(["train", "--set", setting, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert all(name in err for name in names), err
    assert not (out / "config.yaml").exists()
