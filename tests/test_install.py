"""A non-editable `pip install .` into a fresh venv is a working corn_drake: the console script
runs and the teacher diagram builds from the robot model and YAMLs shipped inside the package,
from a folder outside the checkout, with the checkout nowhere on the path.

No network: the fresh venv reaches the heavy dependencies (drake, torch, ...) of the environment
running this test through one .pth line holding a plain path to its site-packages. A plain path
adds the folder to sys.path without running the .pth files inside it, so an editable install of
corn_drake living there (its __editable__*.pth finder) stays inactive: only the package
installed into the fresh venv can be imported.
"""

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import pytest

from corn_drake.contract import HAND_STATE_DIM
from corn_drake.package_data import SHIPPED_FOLDERS
from tests.paths import REPO_ROOT

pytestmark = pytest.mark.slow

# The build reads the package, its metadata and the shipped folders; the rest of the checkout
# (and what a local run left in it) stays behind. pip builds in the copy, so the checkout gets
# no build/ or *.egg-info from this test.
# What a copy of the checkout leaves behind: caches anywhere; the checkout's own output and doc
# folders only at its top (the package has a room named runs/ too: corn_drake/rl/runs).
ANYWHERE = shutil.ignore_patterns(".git", ".venv", "*.egg-info", "__pycache__", ".pytest_cache",
                                  ".ipynb_checkpoints", "_data")
AT_THE_TOP = {"build", "runs", "data", "reports", "docs", "notebooks", "tests"}


def left_behind(folder: str, names: list[str]) -> set[str]:
    top = AT_THE_TOP & set(names) if Path(folder).resolve() == REPO_ROOT.resolve() else set()
    return set(ANYWHERE(folder, names)) | top

SNIPPET = """
import json, sys
import corn_drake
from corn_drake.builders.teacher import build_teacher_diagram
from corn_drake.package_data import diagrams_dir, models_dir

teacher = build_teacher_diagram()
context = teacher.diagram.CreateDefaultContext()
hand = teacher.diagram.GetOutputPort("obs.hand_state").Eval(context)
print(json.dumps({
    "corn_drake": corn_drake.__file__,
    "modules": sorted({m.__file__ for name, m in sys.modules.items()
                       if name.startswith("corn_drake") and getattr(m, "__file__", None)}),
    "models": str(models_dir()), "diagrams": str(diagrams_dir()),
    "finders": [repr(f) for f in sys.meta_path], "path": sys.path,
    "hand": [float(x) for x in hand],
}))
"""


def _run(cmd, cwd, env):
    result = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, f"{cmd} failed:\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    return result.stdout


def _files(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")
            if p.is_file() and "__pycache__" not in p.parts and not p.name.startswith(".")}


def test_pip_install_non_editable_ships_the_model_and_yamls(tmp_path):
    source, env_dir, elsewhere = tmp_path / "src", tmp_path / "venv", tmp_path / "elsewhere"
    shutil.copytree(REPO_ROOT, source, ignore=left_behind)
    elsewhere.mkdir()
    venv.EnvBuilder(with_pip=False).create(env_dir)
    python = env_dir / "bin" / "python"
    # This test's own interpreter's environment holds the dependencies (a fresh clone's .venv
    # under `make test`): found from sys.executable's sysconfig, never from a fixed path.
    dependencies = sorted({sysconfig.get_paths()[k] for k in ("purelib", "platlib")})
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env.update(PIP_NO_INPUT="1", PIP_DISABLE_PIP_VERSION_CHECK="1", PYTHONNOUSERSITE="1")
    site = Path(_run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                     elsewhere, env).strip())
    (site / "_dependencies.pth").write_text("".join(f"{d}\n" for d in dependencies))

    _run([str(python), "-m", "pip", "install", "--no-deps", "--no-build-isolation", "--no-index",
          "-q", str(source)], elsewhere, env)

    help_text = _run([str(env_dir / "bin" / "corn-drake"), "demo", "--help"], elsewhere, env)
    assert "--out" in help_text and "usage: corn-drake demo" in help_text

    report = json.loads(_run([str(python), "-c", SNIPPET], elsewhere, env).strip().splitlines()[-1])
    package = site / "corn_drake"
    assert Path(report["corn_drake"]) == package / "__init__.py"
    # Every corn_drake module came from the venv, none from the checkout or its editable finder.
    assert report["modules"] and all(Path(m).is_relative_to(package) for m in report["modules"])
    assert not any("editable" in f.lower() for f in report["finders"]), report["finders"]
    assert not any(Path(p).resolve() == REPO_ROOT for p in report["path"] if p)
    assert Path(report["models"]) == package / "_data" / "models"
    assert Path(report["diagrams"]) == package / "_data" / "diagrams"
    assert len(report["hand"]) == HAND_STATE_DIM and all(abs(x) < 10 for x in report["hand"])
    # Every file of the shipped folders (subfolders too) is in the package, nothing else.
    for name in SHIPPED_FOLDERS:
        assert _files(package / "_data" / name) == _files(REPO_ROOT / name), name
