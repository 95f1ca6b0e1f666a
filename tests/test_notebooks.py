"""Executes the notebooks in notebooks/ that need no prepared data (each must run clean)."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from corn_drake import REPO_ROOT
from corn_drake.systems.cameras import rendering_available

# Notebooks that record an episode leave a standalone Meshcat HTML file; the perception
# notebook also leaves its depth images.
RECORDING_NOTEBOOKS = {"01_scene_and_controller.ipynb", "04_teacher_rollout.ipynb",
                       "05_perception.ipynb"}
EXPECTED_FIGURES = {"05_perception.ipynb": ["05_depth_images.png"]}
NEEDS_RENDERING = {"05_perception.ipynb"}
NOTEBOOKS = ["01_scene_and_controller.ipynb", "02_objects.ipynb", "03_contact_pretraining.ipynb",
             "04_teacher_rollout.ipynb", "05_perception.ipynb"]


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_runs(name, tmp_path, monkeypatch):
    if name in NEEDS_RENDERING:
        ok, reason = rendering_available()
        if not ok:
            pytest.skip(reason)
    monkeypatch.setenv("CORN_DRAKE_NOTEBOOK_OUT", str(tmp_path))
    # The kernel must import this checkout's corn_drake (worktrees share one venv).
    monkeypatch.setenv("PYTHONPATH", str(REPO_ROOT))
    nb = nbformat.read(REPO_ROOT / "notebooks" / name, as_version=4)
    NotebookClient(nb, timeout=600, kernel_name="python3",
                   resources={"metadata": {"path": str(REPO_ROOT)}}).execute()
    if name in RECORDING_NOTEBOOKS:
        outputs = list(Path(tmp_path).glob("*.html"))
        assert outputs and all(p.stat().st_size > 10_000 for p in outputs)
    for figure in EXPECTED_FIGURES.get(name, []):
        assert (Path(tmp_path) / figure).is_file(), figure
