"""No file of the package is one git ignores: a clean clone (what CI and every user get) would
lack it. `.gitignore`'s runs/ (the output folder) once also hid corn_drake/rl/runs/, and its
modules were left out of a commit while every test here passed."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from tests.paths import REPO_ROOT


@pytest.mark.skipif(shutil.which("git") is None or not (REPO_ROOT / ".git").exists(),
                    reason="not a git checkout")
def test_no_package_file_is_ignored_by_git():
    # _data/ is a build's copy of models/ and diagrams/ (setup.py), ignored on purpose.
    files = [str(p.relative_to(REPO_ROOT)) for p in (REPO_ROOT / "corn_drake").rglob("*")
             if p.is_file() and not {"__pycache__", "_data"} & set(p.parts)
             and p.suffix != ".pyc"]
    assert len(files) > 100  # the package was found (not vacuous)
    ignored = subprocess.run(["git", "check-ignore", "--no-index", "--stdin"], cwd=REPO_ROOT,
                             input="\n".join(files), capture_output=True, text=True).stdout
    assert ignored.split() == []
