"""`corn-drake compare`: evaluation reports in one table, at equal steps and at equal time."""

import json

from corn_drake.cli import main
from corn_drake.storage.atomic_files import write_json


def _report(path, policy, successes, run="", seeds=None, env_steps=4096):
    seeds = seeds or list(range(len(successes)))
    episodes = [{"object": f"obj_{i % 2}", "seed": s, "success": ok}
                for i, (s, ok) in enumerate(zip(seeds, successes))]
    rate = sum(successes) / len(successes)
    write_json(path, {"policy": policy, "success_rate": rate, "balanced_success_rate": rate,
                      "episodes": episodes, "env_steps": env_steps, "run": str(run)})
    return str(path)


def test_compare_tables_success_with_intervals_and_the_equal_time_columns(tmp_path, capsys):
    a = _report(tmp_path / "eval_a.json", "corn", [True, True, True, False], run=tmp_path / "ra")
    b = _report(tmp_path / "eval_b.json", "state", [False, False, True, False], run=tmp_path / "rb")
    summary = tmp_path / "s.json"
    write_json(summary, {"runs_at_equal_time": {"hours": 1.5, "runs": {
        "corn (ra)": {"run": str(tmp_path / "ra"), "step": 2048, "hours": 1.5,
                      "training_success_rate": 0.4, "final_step": 4096, "final_hours": 3.0},
        "state (rb)": {"run": str(tmp_path / "rb"), "step": 4096, "hours": 1.5,
                       "training_success_rate": 0.2, "final_step": 4096, "final_hours": 1.5}}}})
    out = tmp_path / "table.md"
    assert main(["compare", "--report", a, "--report", b, "--summary", str(summary),
                 "--out", str(out)]) == 0
    table = out.read_text().splitlines()
    # 3 of 4: 0.75 +- 1.96 * sqrt(0.75 * 0.25 / 4) = 0.424.
    assert table[2].startswith("| corn | 4,096 | 0.750 ± 0.424 | 0.750 |")
    assert table[2].endswith("| 3.00 | 2,048 | 0.40 |")
    assert table[3].startswith("| state | 4,096 | 0.250 ± 0.424 |")
    assert "warning" not in capsys.readouterr().out


def test_compare_refuses_reports_on_other_episodes_or_without_the_keys(tmp_path, capsys):
    a = _report(tmp_path / "a.json", "corn", [True, False])
    other = _report(tmp_path / "b.json", "state", [True, False], seeds=[7, 8])
    assert main(["compare", "--report", a, "--report", other]) == 2
    assert f"--report {other}: its episodes" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"policy": "corn"}))
    assert main(["compare", "--report", str(bad)]) == 2
    assert "no success_rate" in capsys.readouterr().err
    assert main(["compare", "--report", a, "--summary", a]) == 2
    assert "no runs_at_equal_time" in capsys.readouterr().err
    unequal = _report(tmp_path / "c.json", "state", [True, True], env_steps=99)
    assert main(["compare", "--report", a, "--report", unequal]) == 0
    assert "different env steps" in capsys.readouterr().out
