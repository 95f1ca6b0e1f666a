"""Executes the notebooks in notebooks/ that need no prepared data (each must run clean), and
checks that the plotting ones show their figures inline."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from corn_drake.systems.cameras import rendering_available
from tests.paths import REPO_ROOT

# Notebooks that record an episode leave a standalone Meshcat HTML file; the perception
# notebook also leaves its depth images.
RECORDING_NOTEBOOKS = {"01_scene_and_controller.ipynb", "04_teacher_rollout.ipynb",
                       "05_perception.ipynb", "06_student.ipynb"}
EXPECTED_FIGURES = {"05_perception.ipynb": ["05_depth_images.png", "05_tracking_error.png"]}
# How many figures each plotting notebook shows inline (image outputs of its cells).
INLINE_FIGURES = {"04_teacher_rollout.ipynb": 1, "05_perception.ipynb": 2, "06_student.ipynb": 2,
                  "07_results.ipynb": 11}
# 04 renders a gallery still; 06 runs the student's cameras.
NEEDS_RENDERING = {"04_teacher_rollout.ipynb", "05_perception.ipynb", "06_student.ipynb"}
# 02 builds an object library and 03 contact data (about 50 and 30 s measured); 04 and 06 build
# two unseen objects (about a minute each), the others take seconds.
SLOW = {"02_objects.ipynb", "03_contact_pretraining.ipynb"}
NOTEBOOKS = [pytest.param(name, marks=[pytest.mark.slow] if name in SLOW else [])
             for name in sorted(p.name for p in (REPO_ROOT / "notebooks").glob("*.ipynb"))]


def _image_outputs(nb) -> int:
    return sum("image/png" in out.get("data", {}) for cell in nb.cells if cell.cell_type == "code"
               for out in cell.get("outputs", []))


def _text_outputs(nb) -> str:
    return "\n".join(str(out.get("text", "")) + str(out.get("data", {}).get("text/markdown", ""))
                     for cell in nb.cells if cell.cell_type == "code"
                     for out in cell.get("outputs", []))


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_runs(name, tmp_path, monkeypatch):
    if name in NEEDS_RENDERING:
        ok, reason = rendering_available()
        if not ok:
            pytest.skip(reason)
    monkeypatch.setenv("CORN_DRAKE_NOTEBOOK_OUT", str(tmp_path))
    # The kernel must import this checkout's corn_drake (worktrees share one venv).
    monkeypatch.setenv("PYTHONPATH", str(REPO_ROOT))
    # A non-interactive default backend, as a headless user's environment may set: figures
    # still appear inline only if the notebook itself asks for the inline backend.
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = nbformat.read(REPO_ROOT / "notebooks" / name, as_version=4)
    NotebookClient(nb, timeout=600, kernel_name="python3",
                   resources={"metadata": {"path": str(REPO_ROOT)}}).execute()
    if name in RECORDING_NOTEBOOKS:
        outputs = list(Path(tmp_path).glob("*.html"))
        assert outputs and all(p.stat().st_size > 10_000 for p in outputs)
    for figure in EXPECTED_FIGURES.get(name, []):
        assert (Path(tmp_path) / figure).is_file(), figure
    assert _image_outputs(nb) == INLINE_FIGURES.get(name, 0)
    if name == "07_results.ipynb":  # every result is labelled with its side of the fixes
        text = _text_outputs(nb)
        assert "before the fidelity fixes" in text and "after the fidelity fixes" in text
        assert "not labelled here" not in text


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
