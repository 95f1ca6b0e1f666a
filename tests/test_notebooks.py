"""Executes the notebooks in notebooks/ that need no prepared data (each must run clean)."""

import os
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from corn_drake import REPO_ROOT

RECORDING_NOTEBOOKS = {"01_scene_and_controller.ipynb", "04_teacher_rollout.ipynb"}
NOTEBOOKS = ["01_scene_and_controller.ipynb", "02_objects.ipynb", "03_contact_pretraining.ipynb",
             "04_teacher_rollout.ipynb"]


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_runs(name, tmp_path, monkeypatch):
    monkeypatch.setenv("CORN_DRAKE_NOTEBOOK_OUT", str(tmp_path))
    nb = nbformat.read(REPO_ROOT / "notebooks" / name, as_version=4)
    NotebookClient(nb, timeout=600, kernel_name="python3",
                   resources={"metadata": {"path": str(REPO_ROOT)}}).execute()
    # Notebooks that record an episode leave a standalone Meshcat HTML file.
    if name in RECORDING_NOTEBOOKS:
        outputs = list(Path(tmp_path).glob("*.html"))
        assert outputs and all(p.stat().st_size > 10_000 for p in outputs)
