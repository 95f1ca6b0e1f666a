"""`corn-drake merge-reports`: one report from the parts that split runs played.

`evaluate --run RUN --episodes-from A --episodes B --report PART` (any kind of run, the 6D
expert's too) plays episodes A..B-1 and keeps them in PART's rows file (PART with .rows.jsonl for .json); several such parts, run in
other processes, sessions or machines, are merged here into the report of all their episodes,
after checking that they share every setting, that every row is the episode its number says
(its object and seed) within its part's requested range, and that no episode comes twice
(evaluation/report_merge.py); the episodes asked for and missing are said. Their labels files
(REPORT.labels.jsonl.gz) join into the merged report's: `corn-drake label`'s parts merge the same
way.
"""

from __future__ import annotations

from pathlib import Path

NAME = "merge-reports"
HELP = "merge the rows files of an evaluation split by episode range into one report"


def add_arguments(parser):
    parser.add_argument("parts", nargs="+", type=Path, metavar="ROWS",
                        help="the parts' REPORT.rows.jsonl files (written by `evaluate "
                             "--episodes-from ...`)")
    parser.add_argument("--report", required=True, type=Path,
                        help="the merged report (its rows file is written beside it)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace whatever --report holds (default: a new path, or a "
                             "report of the same run, which a merge rewrites)")


def run(args) -> int:
    from corn_drake.errors import InputError
    from corn_drake.evaluation.episode_rows import rows_path_of, settings_of
    from corn_drake.evaluation.planner_episodes import labels_path_of
    from corn_drake.evaluation.report_merge import merge_reports
    from corn_drake.rl.planner.labels import LABELS_SUFFIX, plain_path_of

    labels_out = args.report.with_name(args.report.stem + LABELS_SUFFIX)
    outputs = {args.report, rows_path_of(args.report),
               labels_out, plain_path_of(labels_out)}
    inputs = {q for p in args.parts
              for q in (p, labels_path_of(p), plain_path_of(labels_path_of(p)))}
    if {p.resolve() for p in outputs} & {p.resolve() for p in inputs}:
        raise InputError(f"--report {args.report}: would overwrite one of its parts")
    from corn_drake.storage.output_owners import check_report_owner

    # Another run's report at --report is not the merge's to replace (issue 63, ownership).
    check_report_owner(args.report, settings_of(args.parts[0]).get("run", "planner"),
                       args.overwrite)
    notes: list[str] = []
    report = merge_reports(args.parts, args.report, notes)
    for note in notes:
        print(f"note: {note}")
    interval = report["success_wilson_95"]
    print(f"{len(report['episodes'])} episodes from {len(args.parts)} parts: success "
          f"{report['success_rate']:.3f}" + (f" (95 % {interval[0]:.3f}-{interval[1]:.3f})"
                                              if interval else "") + f"; report {args.report}")
    return 0
