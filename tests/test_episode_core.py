"""One episode-and-report core for every evaluation (issue 62): a policy's evaluate, like the 6D
expert's, appends each finished episode to REPORT.rows.jsonl, resumes it on a rerun with the same
settings, plays `--episodes-from A --episodes N` only, and merge-reports joins such parts into
the report one process writes; every report carries the Wilson interval and the same
per-episode keys (evaluation/episode_rows.py, report_core.py)."""

import json

from corn_drake.cli import main
from tests.fixtures import one_error_line

SCRIPTED = ["evaluate", "--run", "scripted", "--task", "push", "--set", "task.episode_steps=4",
            "--record", "0", "--no-progress"]
# The keys of a row that physics rounds: compared with a tolerance, the rest exactly.
ROUNDED = ("return", "position_error", "orientation_error", "motion", "end_speed")


def _rows(path):
    lines = path.read_text().splitlines()
    return json.loads(lines[0]), [json.loads(line) for line in lines[1:]]


def _same_episodes(a: list[dict], b: list[dict]) -> None:
    assert [r["episode"] for r in a] == [r["episode"] for r in b]
    for x, y in zip(a, b):
        assert {k: v for k, v in x.items() if k not in ROUNDED} == \
            {k: v for k, v in y.items() if k not in ROUNDED}
        assert abs(x["position_error"] - y["position_error"]) < 1e-4


def test_a_policy_evaluation_writes_rows_and_a_rerun_resumes_them(tmp_path, capsys):
    report = tmp_path / "eval.json"
    assert main([*SCRIPTED, "--episodes", "2", "--report", str(report)]) == 0
    header, rows = _rows(tmp_path / "eval.rows.jsonl")
    assert header["requested"] == [0, 2] and header["settings"]["run"] == "scripted"
    assert [r["episode"] for r in rows] == [0, 1]
    # A longer rerun with the same settings keeps the two rows and plays episode 2 only.
    assert main([*SCRIPTED, "--episodes", "3", "--report", str(report)]) == 0
    header, more = _rows(tmp_path / "eval.rows.jsonl")
    assert more[:2] == rows and [r["episode"] for r in more] == [0, 1, 2]
    written = json.loads(report.read_text())
    assert written["complete"] and written["episodes_requested"] == 3
    low, high = written["success_wilson_95"]
    assert 0.0 <= low <= written["success_rate"] <= high <= 1.0
    assert [r["episode"] for r in written["episodes"]] == [0, 1, 2]


def test_other_settings_into_the_same_report_are_refused_until_overwrite(tmp_path, capsys):
    report = tmp_path / "eval.json"
    assert main([*SCRIPTED, "--episodes", "1", "--report", str(report)]) == 0
    other = [*SCRIPTED, "--set", "task.episode_steps=5", "--episodes", "1", "--report", str(report)]
    before = (tmp_path / "eval.rows.jsonl").read_text()
    assert main(other) == 2
    one_error_line(capsys, "eval.rows.jsonl", "another evaluation", "--overwrite")
    assert (tmp_path / "eval.rows.jsonl").read_text() == before
    assert main([*other, "--overwrite"]) == 0  # started afresh with the new settings
    header, rows = _rows(tmp_path / "eval.rows.jsonl")
    assert "task.episode_steps" in json.dumps(header["settings"]["overrides"])
    assert "5" in json.dumps(header["settings"]["overrides"]) and len(rows) == 1


def test_parts_played_apart_merge_into_the_report_of_one_process(tmp_path, capsys):
    whole, first, second = (tmp_path / f"{n}.json" for n in ("whole", "first", "second"))
    assert main([*SCRIPTED, "--episodes", "4", "--report", str(whole)]) == 0
    assert main([*SCRIPTED, "--episodes", "2", "--report", str(first)]) == 0
    assert main([*SCRIPTED, "--episodes-from", "2", "--episodes", "4",
                 "--report", str(second)]) == 0
    part = json.loads(second.read_text())
    assert part["episodes_from"] == 2 and part["episodes_requested"] == 2
    assert [r["episode"] for r in part["episodes"]] == [2, 3]
    merged = tmp_path / "merged.json"
    assert main(["merge-reports", str(tmp_path / "first.rows.jsonl"),
                 str(tmp_path / "second.rows.jsonl"), "--report", str(merged)]) == 0
    one, two = json.loads(whole.read_text()), json.loads(merged.read_text())
    _same_episodes(one["episodes"], two["episodes"])
    for key in ("task", "action_step", "run", "policy", "success_rate", "success_wilson_95",
                "failure_counts", "complete", "episodes_requested", "overrides"):
        assert one[key] == two[key], key
    # A row edited into another episode's number is refused by the merge, naming the part.
    header, rows = _rows(tmp_path / "second.rows.jsonl")
    rows[0]["episode"] = 3
    (tmp_path / "second.rows.jsonl").write_text(
        "".join(json.dumps(r) + "\n" for r in [header, rows[0]]))
    capsys.readouterr()
    assert main(["merge-reports", str(tmp_path / "first.rows.jsonl"),
                 str(tmp_path / "second.rows.jsonl"), "--report", str(merged)]) == 2
    one_error_line(capsys, "second.rows.jsonl", "episode 3")
