"""`corn-drake compare`: one table of evaluation reports, e.g. the six representations.

Each --report is an `evaluate` report; the table gives its success rate with a 95 % interval
(normal approximation over its episodes), the balanced rate, the env steps the policy was
trained for, and, given `corn-drake curves --summary` of the training runs, each run's
training hours and where it stood at the shortest run's training time (the step reached and
the training success there): the paper's comparison at equal steps and at equal time.

Reports are compared only on the same episodes: the same objects and seeds in the same order
(evaluate with the same --objects, --split, --episodes and --seed); a report whose episodes
differ from the first one's is refused by name.
"""

from __future__ import annotations

import math
from pathlib import Path

NAME = "compare"
HELP = "a table of evaluation reports (success at equal steps; with --summary, at equal time)"
REQUIRED_KEYS = ("policy", "success_rate", "balanced_success_rate", "episodes")


def add_arguments(parser):
    parser.add_argument("--report", action="append", required=True, dest="reports",
                        help="an `evaluate` report JSON (repeat for each row)")
    parser.add_argument("--summary", default="",
                        help="`corn-drake curves --summary` JSON of the reports' training runs (default: none, "
                             "no equal-time columns)")
    parser.add_argument("--out", default="", help="also write the table (markdown) here (default: print only)")


def _episodes_key(report: dict) -> list[tuple]:
    return [(e.get("object"), e.get("seed")) for e in report["episodes"]]


def load_reports(paths: list[str]) -> list[dict]:
    """The reports, checked to hold the keys the table reads and the same episodes."""
    from corn_drake.errors import InputError
    from corn_drake.storage.atomic_files import read_json

    reports = []
    for path in paths:
        report = read_json(path, "evaluation report")
        missing = [k for k in REQUIRED_KEYS if not isinstance(report, dict) or k not in report]
        if missing:
            raise InputError(f"--report {path}: no {', '.join(missing)}; is it written by "
                             "`corn-drake evaluate`?")
        if reports and _episodes_key(report) != _episodes_key(reports[0]):
            raise InputError(f"--report {path}: its episodes (objects and seeds) differ from "
                             f"{paths[0]}'s; evaluate every policy with the same --objects, "
                             "--split, --episodes and --seed")
        reports.append(report | {"path": path})
    return reports


def interval_95(rate: float, n: int) -> float:
    """Half-width of the normal-approximation 95 % interval of a success rate over n episodes."""
    return 1.96 * math.sqrt(rate * (1.0 - rate) / n) if n else float("nan")


def table_rows(reports: list[dict], summary: dict | None) -> list[dict]:
    at_time = {}
    if summary:
        at_time = {row["run"]: row for row in summary["runs_at_equal_time"]["runs"].values()
                   if "run" in row}
    rows = []
    for report in reports:
        n = len(report["episodes"])
        row = {"policy": report["policy"], "report": Path(report["path"]).name,
               "env_steps": report.get("env_steps"), "episodes": n,
               "success_rate": report["success_rate"],
               "interval_95": interval_95(report["success_rate"], n),
               "balanced_success_rate": report["balanced_success_rate"]}
        run = str(Path(report["run"]).resolve()) if report.get("run") else ""
        if run in at_time:
            t = at_time[run]
            row |= {"training_hours": t["final_hours"], "step_at_equal_time": t["step"],
                    "training_success_at_equal_time": t["training_success_rate"]}
        rows.append(row)
    return rows


def markdown(rows: list[dict], hours: float | None) -> str:
    with_time = hours is not None
    head = ["policy", "env steps", "unseen success (95 %)", "balanced", "report"]
    if with_time:
        head += ["training hours", f"step at {hours:.2f} h", f"training success at {hours:.2f} h"]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for r in rows:
        steps = f"{r['env_steps']:,}" if r["env_steps"] is not None else "—"
        cells = [r["policy"], steps, f"{r['success_rate']:.3f} ± {r['interval_95']:.3f}",
                 f"{r['balanced_success_rate']:.3f}", f"`{r['report']}`"]
        if with_time:
            if "training_hours" in r:
                cells += [f"{r['training_hours']:.2f}", f"{r['step_at_equal_time']:,}",
                          f"{r['training_success_at_equal_time']:.2f}"]
            else:
                cells += ["—"] * 3
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def run(args) -> int:
    from corn_drake.storage.atomic_files import ensure_writable, read_json, write_text

    if args.out:
        ensure_writable(Path(args.out).parent, "--out")
    reports = load_reports(args.reports)
    summary = read_json(args.summary, "curves summary") if args.summary else None
    if summary is not None and "runs_at_equal_time" not in summary:
        from corn_drake.errors import InputError

        raise InputError(f"--summary {args.summary}: no runs_at_equal_time; write it with "
                         "`corn-drake curves --summary`")
    rows = table_rows(reports, summary)
    steps = {r["env_steps"] for r in rows if r["env_steps"] is not None}
    text = markdown(rows, summary["runs_at_equal_time"]["hours"] if summary else None)
    if len(steps) > 1:
        text += f"\nwarning: the policies were trained for different env steps ({sorted(steps)})\n"
    print(text, end="")
    if args.out:
        write_text(args.out, text)
        print(f"wrote {args.out}")
    return 0
