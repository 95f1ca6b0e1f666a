"""An output path is new, or holds an artefact of the same kind from the same source, or the
command is refused in one line naming what is there; --overwrite replaces it (issue 63:
`evaluate --report RUN/config.yaml` destroyed a run, and one run's report was replaced by
another's)."""

import json

from corn_drake.cli import main

STILL = ["evaluate", "--run", "still", "--task", "push", "--episodes", "1", "--record", "0",
         "--no-progress", "--set", "task.episode_steps=2"]


def test_evaluate_writes_only_its_own_report_unless_told_to_overwrite(tmp_path, capsys):
    config = tmp_path / "config.yaml"
    config.write_text("total_steps: 100\n")
    assert main([*STILL, "--report", str(config)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds a file that is no JSON report" in err[0]
    assert config.read_text() == "total_steps: 100\n"

    report = tmp_path / "r.json"
    assert main([*STILL, "--report", str(report)]) == 0  # new
    assert main([*STILL, "--report", str(report)]) == 0  # the same run's: replaced
    before = report.read_text()
    capsys.readouterr()
    scripted = ["evaluate", "--run", "scripted", *STILL[3:]]
    assert main([*scripted, "--report", str(report)]) == 2
    assert "holds the report of --run still" in capsys.readouterr().err
    assert report.read_text() == before
    assert main([*scripted, "--report", str(report), "--overwrite"]) == 0
    assert json.loads(report.read_text())["run"] == "scripted"


def test_ship_writes_only_a_new_folder_or_the_same_runs_weights(tmp_path, capsys):
    from tests.fixtures import write_loadable_library
    from tests.paths import REPO_ROOT

    library = write_loadable_library(tmp_path / "lib", 1, 1)
    manifest = (library / "manifest.json").read_bytes()
    shipped = REPO_ROOT / "models" / "weights" / "push_primitive"
    ship = ["ship", "--run", str(shipped), "--report", str(tmp_path / "r.json"),
            "--library-command", f"corn-drake objects --num-objects 2 --out {library}"]
    assert main([*ship, "--out", str(library)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds an object library" in err[0] and "--overwrite" in err[0]
    assert (library / "manifest.json").read_bytes() == manifest
    assert sorted(p.name for p in library.iterdir() if p.name.endswith(".json")) == \
        ["manifest.json"]  # no card written into it
    other = tmp_path / "other_weights"
    other.mkdir()
    (other / "card.json").write_text(json.dumps({"source_run": "runs/another"}))
    assert main([*ship, "--out", str(other)]) == 2
    assert "holds the weights shipped from runs/another" in capsys.readouterr().err
