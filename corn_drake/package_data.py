"""The one place that finds the files corn_drake ships besides code: the robot model (models/)
and the diagram YAMLs (diagrams/, subfolders included).

In the repository both folders sit at the top level, beside the package: the layout a Drake
user expects (one folder with every diagram, one with the robot). A wheel can only ship files
inside its packages, so the build (setup.py, build_py) copies both folders into the package as
corn_drake/_data/models and corn_drake/_data/diagrams. At run time:

- an installed package (`pip install .`, a wheel) finds them in corn_drake/_data/;
- a source checkout (an editable install, or the checkout on PYTHONPATH) has no _data/ and
  uses the top-level folders, so an edited YAML takes effect without reinstalling.

_data/ is looked for first: beside an installed package sits site-packages/, where a folder
called models/ may belong to anything. The checkout's folders count only next to the
checkout's pyproject.toml for the same reason.
"""

from __future__ import annotations

from pathlib import Path

from corn_drake.errors import MissingInputError

PACKAGE_DIR = Path(__file__).resolve().parent
INSTALLED_DATA = PACKAGE_DIR / "_data"  # written by setup.py's build step, never in the repo
CHECKOUT_ROOT = PACKAGE_DIR.parent
SHIPPED_FOLDERS = ("models", "diagrams")  # setup.py copies exactly these


def data_dir(name: str) -> Path:
    """The folder `name` ("models" or "diagrams"): installed copy first, else the checkout's."""
    if name not in SHIPPED_FOLDERS:
        raise ValueError(f"corn_drake ships {SHIPPED_FOLDERS}, not {name!r}")
    installed = INSTALLED_DATA / name
    if installed.is_dir():
        return installed
    checkout = CHECKOUT_ROOT / name
    if checkout.is_dir() and (CHECKOUT_ROOT / "pyproject.toml").is_file():
        return checkout
    raise MissingInputError(
        f"corn_drake's {name}/ folder is missing: looked in {installed} (installed package) and "
        f"{checkout} (source checkout); reinstall with `pip install .` from the repository")


def models_dir() -> Path:
    """The robot model files (models/franka_panda/...)."""
    return data_dir("models")


def diagrams_dir() -> Path:
    """The diagram YAMLs (base diagrams and their subfolders)."""
    return data_dir("diagrams")


def diagram_path(name: str | Path) -> Path:
    """A shipped diagram YAML by its path relative to diagrams/ ("teacher_rollout.yaml",
    "tasks/push.yaml"); the ".yaml" may be left off. Names the available ones when absent."""
    root = diagrams_dir()
    path = root / name
    if path.suffix != ".yaml":
        path = path.with_name(path.name + ".yaml")
    if not path.is_file():
        shipped = sorted(str(p.relative_to(root)) for p in root.rglob("*.yaml"))
        raise MissingInputError(f"no diagram {str(name)!r} in {root}; shipped: {', '.join(shipped)}")
    return path
