"""merge-reports believes a part only as far as it checks (issue 63, provenance): a row must be
the episode its number says (object and seed) inside its part's requested range, no episode
twice, what was asked for and is missing said (and the report then not complete), a line a
kill cut short said and left in its file; an evaluation's rows file claims its range and a
resume with another range is refused. Built from the committed gate A rows (real episodes)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from corn_drake.cli import main
from corn_drake.errors import InputError
from corn_drake.evaluation.episode_rows import claim_range

GATE_A = Path(__file__).resolve().parents[1] / "docs/results/planner/gate_a_policy_first40.rows.jsonl"


@pytest.fixture(scope="module")
def gate_a():
    lines = GATE_A.read_text().splitlines()
    return json.loads(lines[0])["settings"], [json.loads(line) for line in lines[1:6]]


def _part(path: Path, settings: dict, requested, rows) -> Path:
    header = {"settings": settings, **({"requested": list(requested)} if requested else {})}
    path.write_text("".join(json.dumps(r) + "\n" for r in [header, *rows]))
    return path


def test_parts_merge_and_what_is_missing_is_said(gate_a, tmp_path, capsys):
    settings, rows = gate_a
    a = _part(tmp_path / "a.rows.jsonl", settings, (0, 2), rows[:2])
    b = _part(tmp_path / "b.rows.jsonl", settings, (2, 5), rows[2:4])  # episode 4 never played
    with open(b, "a") as f:
        f.write('{"episode": 4, "obj')  # and a kill cut its row short
    before = b.read_text()
    assert main(["merge-reports", str(a), str(b), "--report", str(tmp_path / "m.json")]) == 0
    said = capsys.readouterr().out
    assert "1 of the 5 episodes the parts were asked for are missing: 4" in said
    assert "cut short" in said and b.read_text() == before  # said, the part left as it was
    merged = json.loads((tmp_path / "m.json").read_text())
    assert merged["complete"] is False and merged["episodes_requested"] == 5
    assert [r["episode"] for r in merged["episodes"]] == [0, 1, 2, 3]
    assert merged["success_rate"] == pytest.approx(sum(r["success"] for r in rows[:4]) / 4)


def test_a_copied_or_edited_row_is_refused(gate_a, tmp_path, capsys):
    settings, rows = gate_a
    copied = dict(rows[0], episode=4)  # episode 0's row passed off as episode 4
    a = _part(tmp_path / "a.rows.jsonl", settings, (0, 5), [*rows[:4], copied])
    assert main(["merge-reports", str(a), "--report", str(tmp_path / "m.json")]) == 2
    err = capsys.readouterr().err
    assert "episode 4 names object" in err and "copied or edited" in err
    outside = _part(tmp_path / "o.rows.jsonl", settings, (0, 2), rows[:3])
    assert main(["merge-reports", str(outside), "--report", str(tmp_path / "m.json")]) == 2
    assert "outside the episodes 0..1" in capsys.readouterr().err
    assert not (tmp_path / "m.json").exists()


def test_a_file_without_a_range_is_read_by_the_range_its_rows_span(gate_a, tmp_path):
    settings, rows = gate_a
    old = _part(tmp_path / "old.rows.jsonl", settings, None, [rows[0], rows[2]])
    assert main(["merge-reports", str(old), "--report", str(tmp_path / "m.json")]) == 0
    merged = json.loads((tmp_path / "m.json").read_text())
    assert merged["episodes_requested"] == 3 and merged["complete"] is False


def test_an_evaluation_claims_its_range_and_refuses_another(gate_a, tmp_path):
    settings, rows = gate_a
    path = _part(tmp_path / "r.rows.jsonl", settings, (0, 3), rows[:2])
    claim_range(path, settings, range(0, 3), rows[:2])  # the same range: a resume
    claim_range(path, settings, range(0, 5), rows[:2])  # a larger one: the header grows
    assert json.loads(path.read_text().splitlines()[0])["requested"] == [0, 5]
    assert len(path.read_text().splitlines()) == 3  # the rows kept
    with pytest.raises(InputError, match="holds the evaluation of episodes 0..4"):
        claim_range(path, settings, range(2, 5), rows[:2])
    legacy = _part(tmp_path / "l.rows.jsonl", settings, None, rows[1:3])
    claim_range(legacy, settings, range(0, 4), rows[1:3])  # its rows lie inside: it gets one
    assert json.loads(legacy.read_text().splitlines()[0])["requested"] == [0, 4]
    fresh = tmp_path / "new.rows.jsonl"
    claim_range(fresh, settings, range(7, 9), [])
    assert json.loads(fresh.read_text())["requested"] == [7, 9]


def test_a_merge_does_not_replace_another_runs_report(gate_a, tmp_path, capsys):
    settings, rows = gate_a
    a = _part(tmp_path / "a.rows.jsonl", settings, (0, 2), rows[:2])
    theirs = tmp_path / "theirs.json"
    theirs.write_text(json.dumps({"run": "models/weights/push_primitive", "success_rate": 0.8,
                                  "episodes": []}))
    assert main(["merge-reports", str(a), "--report", str(theirs)]) == 2
    assert "push_primitive" in capsys.readouterr().err
    assert json.loads(theirs.read_text())["success_rate"] == 0.8  # left as it was
    assert main(["merge-reports", str(a), "--report", str(theirs), "--overwrite"]) == 0
    assert json.loads(theirs.read_text())["run"] == "planner"
    # A merged report is the merge's own: merging again rewrites it.
    assert main(["merge-reports", str(a), "--report", str(theirs)]) == 0
