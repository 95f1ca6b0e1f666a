"""The package's import rules (docs/architecture.md), checked on every corn_drake import, the ones
inside functions too: each module imports only from its own folder or from a lower layer, so no
arrow runs upward and no circle can form; `nn/` never imports Drake; `scene/` never imports
`assets/`; the package root holds only the modules listed in ROOT_MODULES."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "corn_drake"

# Lower number = lower floor. A unit is a subpackage, or a module at the package root.
LAYERS = {
    "errors": 0, "transforms": 0, "signals": 0,
    "package_data": 1, "contract": 1, "timing": 1, "storage": 1,
    "__init__": 2,
    "config": 3,
    "nn": 4, "scene": 4,
    "assets": 5, "systems": 5,
    "contact": 6, "tasks": 6,
    "viz": 7, "pretext": 7,
    "builders": 8, "pretraining": 8, "run_folders": 8,
    "rl": 9,
    "evaluation": 10,
    "arguments": 11,
    "bench": 12,
    "commands": 13,
    "cli": 14,
}
# The package root: the CLI entry, the shapes every layer shares, errors, the data-file finder,
# pose math and the policy clock (each imported from several floors, so none belongs to one).
ROOT_MODULES = {"__init__", "cli", "contract", "errors", "package_data", "signals", "timing",
                "transforms"}


def _unit(module: str) -> str:
    """'corn_drake.config.loader' -> 'config'; 'corn_drake' -> '__init__'."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, imported corn_drake module) of every import in `path`, nested ones included."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module == "corn_drake":  # `from corn_drake import X`: X is a module or a name
                found += [(node.lineno, f"corn_drake.{a.name}" if (PACKAGE / f"{a.name}.py").exists()
                           or (PACKAGE / a.name).is_dir() else "corn_drake") for a in node.names]
            elif node.module.startswith("corn_drake."):
                found.append((node.lineno, node.module))
        elif isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if a.name.startswith("corn_drake")]
    return found


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        if "_data" in path.relative_to(PACKAGE).parts:
            continue
        yield path, _unit(".".join(("corn_drake", *path.relative_to(PACKAGE).with_suffix("").parts)))


def upward_imports(layers: dict[str, int]) -> list[str]:
    bad = []
    for path, unit in _modules():
        for line, target in _imports(path):
            other = _unit(target)
            if other != unit and layers[other] >= layers[unit]:
                bad.append(f"{path.relative_to(PACKAGE)}:{line} ({unit}, layer {layers[unit]}) "
                           f"imports {target} ({other}, layer {layers[other]})")
    return bad


def test_every_unit_has_a_layer():
    units = {unit for _, unit in _modules()}
    assert units - set(LAYERS) == set(), "add new packages to LAYERS (and docs/architecture.md)"


def test_no_import_runs_upward_or_sideways_between_units():
    assert upward_imports(LAYERS) == []


def test_the_check_catches_an_upward_import():
    # The same check with config moved above rl must flag config's users below it, so the rule
    # is not passing vacuously.
    moved = dict(LAYERS, config=10)
    assert any("imports corn_drake.config" in line for line in upward_imports(moved))


def test_package_root_holds_only_the_listed_modules():
    root = {p.stem for p in PACKAGE.glob("*.py")}
    assert root == ROOT_MODULES
    assert len(root) <= 8


@pytest.mark.parametrize("unit", ["nn"])
def test_nn_never_imports_drake(unit):
    for path in (PACKAGE / unit).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not any(n.startswith("pydrake") for n in names), path


def test_scene_never_imports_assets():
    for path in (PACKAGE / "scene").rglob("*.py"):
        assert not any(_unit(t) == "assets" for _, t in _imports(path)), path


def test_no_circle_between_modules():
    graph = {}
    for path, _ in _modules():
        name = ".".join(("corn_drake", *path.relative_to(PACKAGE).with_suffix("").parts))
        name = name.removesuffix(".__init__")
        graph[name] = {t for _, t in _imports(path)}
    state, cycle = {}, []

    def visit(node, stack):
        state[node] = "open"
        for nxt in graph.get(node, ()):
            if nxt not in graph:
                continue
            if state.get(nxt) == "open":
                cycle.append(stack[stack.index(nxt):] + [nxt] if nxt in stack else [node, nxt])
            elif nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = "done"

    for node in graph:
        if node not in state:
            visit(node, [node])
    assert cycle == []


# A room a newcomer reads at a glance (issue 52): rl/ holds shared helpers at its top and one
# folder per role (envs/, ppo/, primitive/, workers/), none past a dozen modules.
MAX_RL_TOP_MODULES = 10
MAX_RL_FOLDER_MODULES = 12


def folder_sizes() -> dict[str, int]:
    """{folder relative to the package: .py modules directly inside it}, data folders excluded."""
    sizes = {}
    for folder in [PACKAGE, *sorted(p for p in PACKAGE.rglob("*") if p.is_dir())]:
        rel = folder.relative_to(PACKAGE).as_posix()
        if "_data" in rel or "__pycache__" in rel:
            continue
        sizes[rel] = len(list(folder.glob("*.py")))
    return sizes


def test_rl_is_split_into_rooms_none_over_a_dozen_modules():
    sizes = folder_sizes()
    assert sizes["rl"] <= MAX_RL_TOP_MODULES, f"rl/ has {sizes['rl']} modules at its top"
    too_big = {f: n for f, n in sizes.items() if f.startswith("rl/") and n > MAX_RL_FOLDER_MODULES}
    assert too_big == {}
    assert len([f for f in sizes if f.startswith("rl/")]) >= 4  # the rooms exist (not vacuous)


def _imports_experiments(path: Path) -> list[int]:
    """Lines of `path` that import the experiments package (studies outside the product)."""
    lines = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                 [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0
                 else [])
        lines += [node.lineno for n in names if n == "experiments" or n.startswith("experiments.")]
    return lines


def test_the_package_never_imports_the_experiments(tmp_path):
    """experiments/ imports corn_drake like any user; never the other way round, so a study can
    be deleted without touching the product."""
    bad = [f"{path.relative_to(PACKAGE)}:{line}" for path, _ in _modules()
           for line in _imports_experiments(path)]
    assert bad == []
    # The check sees both import forms, nested ones too.
    probe = tmp_path / "probe.py"
    probe.write_text("def f():\n    import experiments.x\n    from experiments import y\n")
    assert _imports_experiments(probe) == [2, 3]
