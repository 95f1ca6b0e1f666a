"""`corn-drake --help` and an argument error answer at once: building the parser imports none of
the heavy libraries (torch, Drake, numpy, ...), which took 1-7 s before any output. Checked by
what a fresh interpreter has imported, not by a time, so a busy machine cannot fail it."""

import json
import os
import subprocess
import sys

from tests.paths import REPO_ROOT

HEAVY = ("torch", "pydrake", "numpy", "open3d", "ray", "matplotlib", "scipy", "trimesh", "tqdm",
         "gymnasium", "yaml")

# Every parser's help rendered (subcommands and `bench WHAT` too), then a mistyped flag: what
# `corn-drake ... --help` and a typo run, in one fresh process.
PROBE = r"""
import argparse, json, sys
from corn_drake.cli import build_parser

def walk(parser):
    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                yield from walk(sub)

parser = build_parser()
helps = sum(len(p.format_help()) > 0 for p in walk(parser))
try:
    parser.parse_args(["train", "--out", "x", "--stepz", "3"])
except SystemExit as e:
    code = e.code
print(json.dumps({"helps": helps, "code": code,
                  "modules": sorted({m.split(".")[0] for m in sys.modules})}))
"""


def test_building_the_parser_imports_no_heavy_library():
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT),
                                                         os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-c", PROBE], env=env, cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["helps"] > 20 and result["code"] == 2, result  # every parser, and the typo
    assert "error: unrecognized arguments: --stepz" in proc.stderr
    loaded = [name for name in HEAVY if name in result["modules"]]
    assert loaded == [], f"building the parser imported {loaded}"
