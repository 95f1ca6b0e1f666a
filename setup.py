"""Build step only (the project's metadata is in pyproject.toml): a wheel ships the top-level
models/ and diagrams/ folders inside the package as corn_drake/_data/, where
corn_drake/package_data.py finds them once installed. An editable install copies nothing: it
reads the checkout's folders directly."""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
SHIPPED_FOLDERS = ("models", "diagrams")  # the same names as corn_drake.package_data
IGNORED = shutil.ignore_patterns("__pycache__", "*.pyc", ".*")


class BuildPyWithData(build_py):
    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return
        for name in SHIPPED_FOLDERS:
            target = Path(self.build_lib) / "corn_drake" / "_data" / name
            if target.exists():  # a previous build's copy may hold files removed since
                shutil.rmtree(target)
            shutil.copytree(ROOT / name, target, ignore=IGNORED)

    def get_outputs(self, include_bytecode=True):
        copied = [str(p) for name in SHIPPED_FOLDERS
                  for p in (Path(self.build_lib) / "corn_drake" / "_data" / name).rglob("*")
                  if p.is_file()]
        return super().get_outputs(include_bytecode) + copied


setup(cmdclass={"build_py": BuildPyWithData})
