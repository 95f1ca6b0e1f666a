"""Paths of this checkout, for tests that run its code in a subprocess or read its notebooks
(the package itself finds its data through corn_drake.package_data, installed or not)."""

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent
