"""corn_drake.package_data: the one resolver of models/ and diagrams/ (installed copy first, else
the source checkout's folders), and nothing else in the package looks for them on its own."""

import re

import pytest

import corn_drake
from corn_drake import package_data
from corn_drake.errors import MissingInputError
from corn_drake.package_data import data_dir, diagram_path, diagrams_dir, models_dir
from tests.paths import REPO_ROOT


def _tree(root, files):
    for name in files:
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text("x: 1\n")
    return root


def test_a_checkout_uses_its_top_level_folders():
    assert models_dir() == REPO_ROOT / "models" and diagrams_dir() == REPO_ROOT / "diagrams"
    assert corn_drake.MODELS_DIR == models_dir() and corn_drake.DIAGRAMS_DIR == diagrams_dir()
    assert (models_dir() / "franka_panda" / "panda.urdf").is_file()
    with pytest.raises(AttributeError, match="NO_SUCH"):
        corn_drake.NO_SUCH_DIR


def test_an_installed_copy_comes_first(tmp_path, monkeypatch):
    installed = _tree(tmp_path / "_data", ["models/robot.urdf", "diagrams/base.yaml"])
    monkeypatch.setattr(package_data, "INSTALLED_DATA", installed)
    assert models_dir() == installed / "models" and diagrams_dir() == installed / "diagrams"
    assert corn_drake.DIAGRAMS_DIR == installed / "diagrams"  # the package constants follow


def test_folders_count_only_beside_the_checkouts_pyproject(tmp_path, monkeypatch):
    """Beside an installed package is site-packages/, where a models/ may be anyone's."""
    site = _tree(tmp_path / "site-packages", ["models/other.txt"])
    monkeypatch.setattr(package_data, "INSTALLED_DATA", site / "corn_drake" / "_data")
    monkeypatch.setattr(package_data, "CHECKOUT_ROOT", site)
    with pytest.raises(MissingInputError, match=re.escape(str(site / "corn_drake" / "_data" / "models"))
                       + ".*" + re.escape(str(site / "models"))):
        models_dir()
    (site / "pyproject.toml").write_text("")
    assert models_dir() == site / "models"


def test_only_the_shipped_folders_are_resolved():
    with pytest.raises(ValueError, match="'notebooks'"):
        data_dir("notebooks")


def test_diagram_path_takes_names_with_or_without_yaml_and_subfolders(tmp_path, monkeypatch):
    installed = _tree(tmp_path / "_data", ["models/robot.urdf", "diagrams/base.yaml",
                                           "diagrams/tasks/push.yaml"])
    monkeypatch.setattr(package_data, "INSTALLED_DATA", installed)
    assert diagram_path("base") == diagram_path("base.yaml") == installed / "diagrams" / "base.yaml"
    assert diagram_path("tasks/push") == installed / "diagrams" / "tasks" / "push.yaml"
    with pytest.raises(MissingInputError, match=r"no diagram 'tasks/pull'.*shipped: base\.yaml, tasks/push\.yaml"):
        diagram_path("tasks/pull")


def test_no_other_module_finds_files_relative_to_the_source_tree():
    """Everything that finds the model or the YAMLs goes through package_data."""
    pattern = re.compile(r"parent\.parent|parents\[")  # how REPO_ROOT used to be found
    offenders = [str(p.relative_to(REPO_ROOT)) for p in (REPO_ROOT / "corn_drake").rglob("*.py")
                 if p.name != "package_data.py" and pattern.search(p.read_text())]
    assert not offenders, offenders
