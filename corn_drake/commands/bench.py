"""`corn-drake bench <what> --report FILE.json`: the one way speed and memory numbers are made.

Each module in `corn_drake.bench` with `NAME`, `HELP`, `add_arguments(parser)` and
`run(args) -> dict` is a benchmark; its dict (figure + same-run baseline) goes to the report,
together with a description of the machine.
"""

from __future__ import annotations

import importlib
import pkgutil

from corn_drake import bench as bench_pkg

NAME = "bench"
HELP = "measure speed/memory; writes a JSON report with the figure and its same-run baseline"


def _bench_modules():
    """Every module of bench/ and its role folders that defines a benchmark (NAME and run), in
    the order of their names."""
    found = pkgutil.walk_packages(bench_pkg.__path__, f"{bench_pkg.__name__}.")
    for info in sorted(found, key=lambda m: m.name.rsplit(".", 1)[-1]):
        short = info.name.rsplit(".", 1)[-1]
        if info.ispkg or short.startswith("_") or short == "report":
            continue
        module = importlib.import_module(info.name)
        if hasattr(module, "NAME") and hasattr(module, "run"):
            yield module


def add_arguments(parser):
    sub = parser.add_subparsers(dest="bench", required=True, metavar="WHAT")
    for module in _bench_modules():
        p = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        p.add_argument("--report", required=True, help="path of the JSON report to write")
        module.add_arguments(p)
        # _prog: an input error is reported as `corn-drake bench NAME: error: ...`
        p.set_defaults(_bench_run=module.run, _bench_name=module.NAME, _prog=p.prog)


def run(args) -> int:
    from corn_drake.bench.report import write_report

    result = args._bench_run(args)
    report = write_report(args.report, args._bench_name, result)
    print(f"wrote {args.report}")
    for key, value in report["results"].items():
        if not isinstance(value, (dict, list)):
            print(f"  {key}: {value}")
    return 0
