"""Executes the notebooks in notebooks/ that need no prepared data (each must run clean), and
checks that the plotting ones show their figures inline.

The notebooks are committed with their outputs, so they read on a code host without being run.
Each run checks that the committed outputs are still what the code makes: per code cell, the
kinds of output it shows (figures, tables, printed text) must match what this run produced,
and no committed cell may hold an error. After changing a notebook or what it shows, refresh
the committed outputs with

    CORN_DRAKE_WRITE_NOTEBOOKS=1 .venv/bin/python -m pytest tests/test_notebooks.py -m ""

which writes the outputs with the run's temporary folder shown as the default runs/notebooks and
this checkout's root as relative paths: every committed notebook must show a figure and name no
machine's folder (test_committed_notebooks_show_a_figure_and_no_machine_paths).
"""

import os
import re
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from corn_drake.systems.perception.cameras import rendering_available
from tests.paths import REPO_ROOT

# Notebooks that record an episode leave a standalone Meshcat HTML file; the perception
# notebook also leaves its depth images.
RECORDING_NOTEBOOKS = {"01_scene_and_controller.ipynb", "04_teacher_rollout.ipynb",
                       "05_perception.ipynb", "06_student.ipynb", "08_contact_primitives.ipynb"}
EXPECTED_FIGURES = {"05_perception.ipynb": ["05_depth_images.png", "05_tracking_error.png"]}
# How many figures each plotting notebook shows inline (image outputs of its cells).
INLINE_FIGURES = {"01_scene_and_controller.ipynb": 1, "02_objects.ipynb": 1,
                  "03_contact_pretraining.ipynb": 1, "04_teacher_rollout.ipynb": 1,
                  "05_perception.ipynb": 2, "06_student.ipynb": 2,
                  "07_results.ipynb": 11, "08_contact_primitives.ipynb": 1}
# 04 renders a gallery still; 06 runs the student's cameras.
NEEDS_RENDERING = {"04_teacher_rollout.ipynb", "05_perception.ipynb", "06_student.ipynb"}
# 02 builds an object library and 03 contact data (about 50 and 30 s measured); 04 builds two
# unseen objects (about a minute), which 06 and 08 then find (shared_out); the others take
# seconds.
SLOW = {"02_objects.ipynb", "03_contact_pretraining.ipynb"}
NOTEBOOKS = [pytest.param(name, marks=[pytest.mark.slow] if name in SLOW else [])
             for name in sorted(p.name for p in (REPO_ROOT / "notebooks").glob("*.ipynb"))]


# An absolute path of one machine (a temporary folder, a home, a checkout) in a committed output
# says nothing to a reader elsewhere; outputs show paths as a run from the repository root with
# the default output folder would (_without_machine_paths).
MACHINE_PATH = re.compile(r"(/tmp/|/var/folders/|/private/|/home/|/root/|/Users/|/work/)")
DEFAULT_OUT = "runs/notebooks"


def _without_machine_paths(nb, out: Path):
    """`nb` with this run's output folder written as the notebooks' default one and this
    checkout's root as the relative path it is, in every text output."""
    def clean(text: str) -> str:
        return text.replace(str(out), DEFAULT_OUT).replace(f"{REPO_ROOT}/", "")

    for cell in nb.cells:
        for out_ in cell.get("outputs", []) if cell.cell_type == "code" else []:
            if "text" in out_:
                out_["text"] = clean(out_["text"])
            for kind, value in out_.get("data", {}).items():
                if kind.startswith("text/") and isinstance(value, str):
                    out_["data"][kind] = clean(value)
    return nb


def _image_outputs(nb) -> int:
    return sum("image/png" in out.get("data", {}) for cell in nb.cells if cell.cell_type == "code"
               for out in cell.get("outputs", []))


def _output_kinds(nb) -> list[list[str]]:
    """Per code cell, the kinds of output it shows: each figure, table or value's MIME types, and
    whether it printed to stdout. stderr (progress bars, library warnings) varies by machine and
    is left out; a committed error output never matches a clean run."""
    kinds = []
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        shown = []
        for out in cell.get("outputs", []):
            if out["output_type"] in ("display_data", "execute_result"):
                shown.append("+".join(sorted(out.get("data", {}))))
            elif out["output_type"] == "stream" and out.get("name") == "stdout":
                if "stdout" not in shown:
                    shown.append("stdout")
            elif out["output_type"] == "error":
                shown.append(f"error: {out.get('ename')}")
        kinds.append(shown)
    return kinds


def _text_outputs(nb) -> str:
    return "\n".join(str(out.get("text", "")) + str(out.get("data", {}).get("text/markdown", ""))
                     for cell in nb.cells if cell.cell_type == "code"
                     for out in cell.get("outputs", []))


@pytest.fixture(scope="module")
def shared_out(tmp_path_factory):
    """One output folder for every notebook, as a user running them in turn has (the default
    runs/notebooks): a library one notebook built is the next one's (02's tiny library is
    03's; 04's two unseen objects are 06's and 08's), as each notebook's first cell reuses
    what it finds. Run alone, a notebook builds what it needs."""
    return tmp_path_factory.mktemp("notebooks")


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_runs(name, shared_out, monkeypatch):
    if name in NEEDS_RENDERING:
        ok, reason = rendering_available()
        if not ok:
            pytest.skip(reason)
    tmp_path = shared_out
    monkeypatch.setenv("CORN_DRAKE_NOTEBOOK_OUT", str(tmp_path))
    # The kernel must import this checkout's corn_drake (worktrees share one venv).
    monkeypatch.setenv("PYTHONPATH", str(REPO_ROOT))
    # A non-interactive default backend, as a headless user's environment may set: figures
    # still appear inline only if the notebook itself asks for the inline backend.
    monkeypatch.setenv("MPLBACKEND", "Agg")
    path = REPO_ROOT / "notebooks" / name
    committed = nbformat.read(path, as_version=4)
    nb = nbformat.read(path, as_version=4)
    # No per-cell timestamps: the committed file changes only where the outputs do.
    NotebookClient(nb, timeout=600, kernel_name="python3", record_timing=False,
                   resources={"metadata": {"path": str(REPO_ROOT)}}).execute()
    if os.environ.get("CORN_DRAKE_WRITE_NOTEBOOKS") == "1":
        nbformat.write(_without_machine_paths(nb, tmp_path), path)
    else:
        assert _output_kinds(committed) == _output_kinds(nb), (
            f"{name}: its committed outputs are stale (see this module's docstring to refresh)")
    if name in RECORDING_NOTEBOOKS:  # its own recordings, named by its number
        outputs = list(Path(tmp_path).glob(f"{name[:2]}_*.html"))
        assert outputs and all(p.stat().st_size > 10_000 for p in outputs)
    for figure in EXPECTED_FIGURES.get(name, []):
        assert (Path(tmp_path) / figure).is_file(), figure
    assert _image_outputs(nb) == INLINE_FIGURES.get(name, 0)
    if name == "07_results.ipynb":  # every result is labelled with its side of the fixes
        text = _text_outputs(nb)
        assert "before the fidelity fixes" in text and "after the fidelity fixes" in text
        assert "not labelled here" not in text


@pytest.mark.parametrize("name", sorted(p.name for p in (REPO_ROOT / "notebooks").glob("*.ipynb")))
def test_committed_notebooks_show_a_figure_and_no_machine_paths(name):
    """Read on a code host, each notebook shows at least one picture, and its outputs name no
    folder of the machine that ran it."""
    nb = nbformat.read(REPO_ROOT / "notebooks" / name, as_version=4)
    assert _image_outputs(nb) >= 1, f"{name}: no figure in its committed outputs"
    text = "\n".join(str(out.get("text", "")) + "".join(
        str(v) for k, v in out.get("data", {}).items() if k.startswith("text/"))
        for cell in nb.cells if cell.cell_type == "code" for out in cell.get("outputs", []))
    found = MACHINE_PATH.findall(text)
    assert not found, f"{name}: its committed outputs name machine paths ({sorted(set(found))})"


def test_library_plots_leave_the_notebook_backend_alone(tmp_path):
    """Notebooks train in their kernel (03, 04): the PNG writers of pretraining and training must
    not switch that kernel's matplotlib backend, or later figures stop showing inline."""
    import matplotlib

    from corn_drake.viz.learning_curves import plot_learning_curves

    inline = "module://matplotlib_inline.backend_inline"
    previous = matplotlib.get_backend()
    matplotlib.use(inline)
    try:
        history = [{"step": 32 * (i + 1), "episodes": 50, "success_rate": 0.1 * i, "return": -0.1}
                   for i in range(4)]
        plot_learning_curves({"state": history}, tmp_path / "curve.png")
        assert matplotlib.get_backend() == inline
        assert (tmp_path / "curve.png").stat().st_size > 1000
    finally:
        matplotlib.use(previous)
    switching = [str(p.relative_to(REPO_ROOT)) for p in (REPO_ROOT / "corn_drake").rglob("*.py")
                 if "matplotlib.use(" in p.read_text()]
    assert not switching, switching
