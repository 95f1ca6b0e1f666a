"""The CLI's own manners (issue 55): --version, "did you mean" for a mistyped flag and --set key
(the refusal rows are in test_cli_bad_input.py), one line instead of a traceback in a Python
without the project's dependencies, and distill's --set/--task."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from corn_drake import __version__
from corn_drake.cli import main

REPO = Path(__file__).resolve().parents[1]


def test_version_names_the_package_python_drake_and_torch(capsys):
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"corn-drake {__version__} (Python ") and "drake 1.51" in out
    assert "torch " in out


def test_a_mistyped_flag_names_the_closest_one_of_its_command(capsys):
    with pytest.raises(SystemExit):
        main(["evaluate", "--run", "scripted", "--episodse", "3", "--report", "r.json"])
    err = capsys.readouterr().err
    assert err.startswith("corn-drake evaluate: error: unrecognized arguments: --episodse 3")
    assert "did you mean --episodes?" in err and len(err.splitlines()) == 1


def test_a_renamed_flag_is_never_suggested(capsys):
    with pytest.raises(SystemExit):
        main(["objects", "--nm", "3", "--out", "x"])
    err = capsys.readouterr().err
    assert "did you mean --num?" not in err


def test_a_python_without_the_dependencies_gets_one_line(tmp_path, monkeypatch, capsys):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "pydrake" else real(name, *a))
    assert main(["train", "--out", str(tmp_path / "run")]) == 1
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "'pydrake'" in err
    assert "venv" in err or "install" in err
    assert not (tmp_path / "run").exists()


def test_a_dependency_missing_at_import_gets_one_line(tmp_path, monkeypatch, capsys):
    from corn_drake.commands.reporting import compare

    def run(args):
        raise ModuleNotFoundError("No module named 'open3d'", name="open3d")

    monkeypatch.setattr(compare, "run", run)
    assert main(["compare", "--report", str(tmp_path / "r.json")]) == 1
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "'open3d'" in err


def test_the_entry_point_without_site_packages_says_how_to_get_them(tmp_path):
    """`python -S` has no site-packages: no numpy, drake or torch, as a bare system Python."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run([sys.executable, "-S", "-m", "corn_drake.cli", "train", "--out",
                           str(tmp_path / "run")], env=env, cwd=tmp_path, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr and len(proc.stderr.splitlines()) == 1, proc.stderr
    assert "corn-drake needs" in proc.stderr


def test_distill_set_reaches_the_student_and_teacher_sections():
    from corn_drake.commands.learning.distill import apply_distill_sets
    from corn_drake.config.training import DistillConfig
    from corn_drake.errors import InputError

    cfg = apply_distill_sets(DistillConfig(), ["task.episode_steps=50", "window=16",
                                               "segmentation.mode=ground_truth"])
    assert cfg.env.teacher.task.episode_steps == 50 and cfg.window == 16
    assert cfg.env.segmentation.mode == "ground_truth"
    with pytest.raises(InputError, match=r"--set task.episode_stepz=3: .*did you mean"):
        apply_distill_sets(DistillConfig(), ["task.episode_stepz=3"])


def test_distill_task_overlays_the_teacher_env():
    from corn_drake.commands.learning.distill import with_task
    from corn_drake.config.plumbing.diagram_files import load_teacher_config

    teacher = load_teacher_config()
    teacher.scene.object.object_id = "kept"
    env = with_task(teacher, "planar")
    assert env.task.name == "planar" and env.scene.object.object_id == "kept"
    assert with_task(teacher, None) is teacher


def test_a_library_recorded_with_the_old_num_spelling_resumes(tmp_path):
    """arguments.json of a library built before --num became --num-objects still guards it."""
    import json

    from corn_drake.commands.datasets.objects import RECORDED_RENAMES
    from corn_drake.errors import InputError
    from corn_drake.run_folders.guards import resume_arguments

    (tmp_path / "arguments.json").write_text(json.dumps({"--num": 4, "--seed": 0}))
    with pytest.raises(InputError, match="--num-objects: recorded 4, requested 2"):
        resume_arguments(tmp_path, {"--num-objects": 2, "--seed": 0}, made_by="objects",
                         may_grow=("--num-objects",), renamed=RECORDED_RENAMES)
    resume_arguments(tmp_path, {"--num-objects": 6, "--seed": 0}, may_grow=("--num-objects",),
                     renamed=RECORDED_RENAMES, made_by="objects")
    assert json.loads((tmp_path / "arguments.json").read_text())["--num-objects"] == 6
