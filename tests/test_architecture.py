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
    """'corn_drake.config.plumbing.loader' -> 'config'; 'corn_drake' -> '__init__'."""
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


# A room a newcomer reads at a glance (issues 52, 62): every folder holds one role and at most a
# dozen modules (its __init__.py not counted), split by role where it grows past that; rl/ keeps
# only shared helpers at its top.
MAX_FOLDER_MODULES = 12
MAX_RL_TOP_MODULES = 10


def folder_sizes() -> dict[str, int]:
    """{folder relative to the package: .py modules directly inside it, __init__.py not
    counted}, data folders excluded; the package root is "."."""
    sizes = {}
    for folder in [PACKAGE, *sorted(p for p in PACKAGE.rglob("*") if p.is_dir())]:
        rel = folder.relative_to(PACKAGE).as_posix()
        if "_data" in rel or "__pycache__" in rel:
            continue
        sizes[rel] = len([p for p in folder.glob("*.py") if p.name != "__init__.py"])
    return sizes


def oversized(sizes: dict[str, int], limit: int = MAX_FOLDER_MODULES) -> dict[str, int]:
    # The root has its own list (ROOT_MODULES); every other folder has the limit.
    return {f: n for f, n in sizes.items() if f != "." and n > limit}


def test_every_folder_holds_at_most_a_dozen_modules():
    sizes = folder_sizes()
    assert oversized(sizes) == {}
    assert sizes["rl"] <= MAX_RL_TOP_MODULES, f"rl/ has {sizes['rl']} modules at its top"
    # Not vacuous: the count sees real folders, and a lower limit flags the biggest.
    assert len(sizes) >= 20 and oversized(sizes, limit=3) != {}


# rl/'s rooms ranked (issue 62): an import from one room of rl/ to another runs to a lower rank,
# imports inside functions counted, so no two rooms lean on each other and each can be read
# knowing only those below it. "" is rl/'s top (the shared helpers). Rooms of one rank do not
# import each other.
RL_ROOM_RANKS = {
    "envs": 0,          # the Drake envs the policies act in
    "": 1,              # device, normalisation, run paths and progress: what every trainer shares
    "ppo": 2,           # the dense teacher's agent and PPO update
    "primitive": 2,     # the contact-primitive agent, TD3, its outcome and value choosers
    "planner": 3,       # the 6D expert's search over a primitive run's candidates
    "workers": 3,       # Ray workers that collect segments or primitives for the trainers
    "imitation": 4,     # fitting the value chooser to the expert's labels
    "training": 5,      # the trainers, which may spread their episodes over workers
    "runs": 6,          # loading any kind of run for the commands
}


def rl_room(module: str) -> str | None:
    """'corn_drake.rl.ppo.agent' -> 'ppo'; 'corn_drake.rl.device' -> ''; None outside rl/."""
    parts = module.split(".")
    if len(parts) < 2 or parts[1] != "rl":
        return None
    return parts[2] if len(parts) > 3 or (len(parts) == 3 and (PACKAGE / "rl" / parts[2]).is_dir()) \
        else ""


def rl_imports_against_rank(ranks: dict[str, int]) -> list[str]:
    bad = []
    for path, _ in _modules():
        name = ".".join(("corn_drake", *path.relative_to(PACKAGE).with_suffix("").parts))
        room = rl_room(name.removesuffix(".__init__") if path.name == "__init__.py" else name)
        if room is None:
            continue
        for line, target in _imports(path):
            other = rl_room(target)
            if other is not None and other != room and ranks[other] >= ranks[room]:
                bad.append(f"{path.relative_to(PACKAGE)}:{line} (rl/{room}, rank {ranks[room]}) "
                           f"imports {target} (rl/{other}, rank {ranks[other]})")
    return bad


def test_every_room_of_rl_has_a_rank():
    rooms = {p.name for p in (PACKAGE / "rl").iterdir() if p.is_dir() and p.name != "__pycache__"}
    assert rooms | {""} == set(RL_ROOM_RANKS), "rank new rl/ rooms in RL_ROOM_RANKS"


def test_rl_rooms_import_only_lower_ranks_function_level_imports_counted():
    assert rl_imports_against_rank(RL_ROOM_RANKS) == []


def test_the_rank_check_sees_a_function_level_import():
    # Ranking workers above the trainers must flag the trainers' imports of workers, which are
    # inside functions (Ray is imported only when a run asks for workers).
    swapped = dict(RL_ROOM_RANKS, workers=6, runs=7)
    flagged = rl_imports_against_rank(swapped)
    assert any(line.startswith("rl/training/") and "rl.workers" in line for line in flagged)


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
