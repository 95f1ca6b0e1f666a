"""Reports and cards that cannot lie (issue 53): a report being written by `evaluate --report`
is locked, so a second evaluate into the same file is refused instead of one result being lost;
`ship` refuses a report that measured other weights than it ships, and a partial report unless
--allow-partial, whose card then says so; the shipped cards' reports pass the same checks."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from corn_drake.cli import main
from corn_drake.storage.checkpoint_files import load_checkpoint, save_checkpoint
from corn_drake.storage.file_locks import lock_path, locked_output
from tests.fixtures import one_error_line
from tests.paths import REPO_ROOT

STILL = ["evaluate", "--run", "still", "--task", "push", "--set", "task.episode_steps=2",
         "--episodes", "1", "--record", "0", "--no-progress"]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT),
                                                     os.environ.get("PYTHONPATH", "")])}
# A process that holds `argv[1]`'s report lock until its stdin closes, saying when it holds it.
HOLDER = ("import sys\n"
          "from corn_drake.storage.file_locks import locked_output\n"
          "with locked_output(sys.argv[1], '--report'):\n"
          "    print('held', flush=True)\n"
          "    sys.stdin.read()\n")


# --- evaluate: one writer per report -----------------------------------------------------------
def test_a_second_evaluate_into_a_report_being_written_is_refused(tmp_path, capsys):
    report = tmp_path / "eval.json"
    old = '{"run": "still", "success_rate": null, "episodes": []}\n'
    report.write_text(old)  # the first evaluate's file (the same run's), still to be replaced
    holder = subprocess.Popen([sys.executable, "-c", HOLDER, str(report)], env=ENV,
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        capsys.readouterr()
        assert main([*STILL, "--report", str(report)]) == 2
        one_error_line(capsys, "--report", str(report), f"pid {holder.pid}")
        # The refused evaluate wrote nothing and left the holder's lock in place.
        assert report.read_text() == old
        assert lock_path(report).read_text().strip() == str(holder.pid)
    finally:
        holder.stdin.close()
        assert holder.wait(timeout=600) == 0
    # Released and removed on exit: the next evaluate writes the report and leaves no lock.
    assert not lock_path(report).exists()
    assert main([*STILL, "--report", str(report)]) == 0
    assert json.loads(report.read_text())["run"] == "still"
    assert not lock_path(report).exists()


def test_a_lock_left_by_a_killed_evaluate_is_taken_over(tmp_path, capsys):
    """kill -9 runs no cleanup: its lock file stays, naming a dead pid. The kernel dropped its
    flock with the process, so the next evaluate takes the file over."""
    report = tmp_path / "eval.json"
    holder = subprocess.Popen([sys.executable, "-c", HOLDER, str(report)], env=ENV,
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "held"
    holder.kill()
    holder.wait(timeout=600)
    assert lock_path(report).read_text().strip() == str(holder.pid)  # the stale file
    assert main([*STILL, "--report", str(report)]) == 0
    assert json.loads(report.read_text())["complete"] is True
    assert not lock_path(report).exists()


def test_a_refused_lock_leaves_no_folder_behind(tmp_path):
    """The lock makes the report's folder; a command that fails before writing the report
    removes what it made."""
    report = tmp_path / "new" / "deeper" / "eval.json"
    with pytest.raises(RuntimeError):
        with locked_output(report, "--report"):
            assert lock_path(report).is_file()
            raise RuntimeError("the run did not load")
    assert not (tmp_path / "new").exists()


# --- ship: the report measured the weights that ship, and is whole ------------------------------
@pytest.fixture
def student_run(tmp_path):
    """A distill run, its library and its own unseen report (evaluate of its 96-step weights)."""
    from tests.fixtures import write_loadable_library
    from tests.test_student_eval import write_distill_run

    library = write_loadable_library(tmp_path / "lib", 1, num_unseen=1)
    run = write_distill_run(tmp_path / "student", episode_steps=2)
    report = tmp_path / "eval_run.json"
    assert main(["evaluate", "--run", str(run), "--objects", str(library), "--split", "unseen",
                 "--episodes", "1", "--record", "0", "--no-progress", "--report",
                 str(report)]) == 0
    return run, library, report


def _ship(run, library, report, out, *flags):
    return main(["ship", "--run", str(run), "--report", str(report), "--library-command",
                 f"corn-drake objects --num-objects 2 --seed 0 --split unseen --out {library}",
                 "--out", str(out), *flags])


def test_a_report_records_the_weights_it_measured_and_ship_refuses_others(student_run, tmp_path,
                                                                          capsys):
    run, library, report = student_run
    data = json.loads(report.read_text())
    # A student's report too says which weights it measured (a teacher's and a primitive
    # run's always did).
    assert data["env_steps"] == 96 and data["checkpoint"] == "last.pt"
    # The run trains on after the report: its last.pt is now at 120 steps.
    ckpt = run / "checkpoints" / "last.pt"
    save_checkpoint(ckpt, {**load_checkpoint(ckpt), "global_step": 120})
    out = tmp_path / "weights" / "student"
    capsys.readouterr()
    assert _ship(run, library, report, out) == 2
    one_error_line(capsys, f"--report {report}", "96", "120", f"--run {run}")
    assert not out.exists() and not out.parent.exists()  # nothing written for a refused run
    # Evaluated again (afresh: its weights changed), the report is of the weights that ship.
    assert main(["evaluate", "--run", str(run), "--objects", str(library), "--split", "unseen",
                 "--episodes", "1", "--record", "0", "--no-progress", "--report",
                 str(report), "--overwrite"]) == 0
    assert _ship(run, library, report, out) == 0
    card = json.loads((out / "card.json").read_text())
    assert card["env_steps"] == 120 and "complete" not in card


def test_ship_refuses_a_partial_report_unless_asked_and_then_its_card_says_so(student_run,
                                                                             tmp_path, capsys):
    run, library, report = student_run
    partial = tmp_path / "partial.json"
    # What an interrupted evaluate writes: the finished episodes, complete false.
    partial.write_text(json.dumps({**json.loads(report.read_text()), "complete": False,
                                   "episodes_requested": 10}))
    out = tmp_path / "weights" / "student"
    capsys.readouterr()
    assert _ship(run, library, partial, out) == 2
    one_error_line(capsys, f"--report {partial}", "complete: false", "--allow-partial")
    assert not out.parent.exists()
    assert _ship(run, library, partial, out, "--allow-partial") == 0
    card = json.loads((out / "card.json").read_text())
    assert card["complete"] is False and card["episodes"] == 1
    assert "partial report" in capsys.readouterr().out


# --- the shipped cards' reports pass the same checks ---------------------------------------------
CARDS = sorted((REPO_ROOT / "models" / "weights").glob("*/card.json"))


@pytest.mark.parametrize("card_path", CARDS, ids=[p.parent.name for p in CARDS])
def test_every_shipped_cards_report_measured_its_weights(card_path, capsys, monkeypatch):
    """What `ship` checks of each shipped card's report: whole, and measured against the
    weights the card ships (a sibling's for an outcome folder: its env_steps are those, see
    test_shipped_weights). The student's report, from before evaluate recorded a student's
    steps, is accepted with its warning (evaluation/shipping.py says how older reports are
    read)."""
    from corn_drake.evaluation.shipping import check_measured_weights

    monkeypatch.chdir(REPO_ROOT)  # cards and reports name repository-relative paths
    card = json.loads(card_path.read_text())
    report = json.loads(Path(card["report"]).read_text())
    # Which run it measured is test_shipped_weights' (one card's source_run is annotated).
    assert report.get("complete", True) is True and "complete" not in card
    check_measured_weights(report, card["report"], card["source_run"], card["env_steps"],
                           "last.pt")
    warned = capsys.readouterr().err
    assert not warned or ("records no env_steps" in warned and card["policy"] == "student")


def test_a_teacher_ships_with_the_cards_keys_and_evaluates_as_the_run(tmp_path, capsys):
    """A teacher run (the shipped push_corn, copied as a run folder) ships through the same
    loading as evaluate: its card has exactly the shipped corn card's keys, its encoder travels
    and the shipped folder replays the run's episode."""
    import shutil

    from tests.fixtures import write_loadable_library

    shipped = REPO_ROOT / "models" / "weights" / "push_corn"
    run = tmp_path / "run"
    shutil.copytree(shipped, run)
    (run / "card.json").unlink()  # a run folder, not a shipped one
    library = write_loadable_library(tmp_path / "lib", 1, num_unseen=1)
    args = ["--objects", str(library), "--split", "unseen", "--episodes", "1", "--record", "0",
            "--no-progress"]
    report = tmp_path / "eval_run.json"
    assert main(["evaluate", "--run", str(run), *args, "--report", str(report)]) == 0
    out = tmp_path / "weights" / "push_corn"
    assert _ship(run, library, report, out, "--train-command", "corn-drake train ...") == 0
    card = json.loads((out / "card.json").read_text())
    assert set(card) == set(json.loads((shipped / "card.json").read_text()))
    assert card["env_steps"] == json.loads(report.read_text())["env_steps"]
    assert card["encoder"]["file"] == "encoder.pt" and (out / "encoder.pt").is_file()
    again = tmp_path / "eval_shipped.json"
    assert main(["evaluate", "--run", str(out), *args, "--report", str(again)]) == 0
    first, second = (json.loads(p.read_text())["episodes"] for p in (report, again))
    assert [e["success"] for e in first] == [e["success"] for e in second]
    assert first[0]["position_error"] == pytest.approx(second[0]["position_error"], abs=1e-6)
