"""Notebook 05 (perception) runs clean and leaves its Meshcat HTML and figures."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from corn_drake import REPO_ROOT
from corn_drake.systems.cameras import rendering_available

ok, reason = rendering_available()


@pytest.mark.skipif(not ok, reason=reason)
def test_notebook_05_runs(tmp_path, monkeypatch):
    monkeypatch.setenv("CORN_DRAKE_NOTEBOOK_OUT", str(tmp_path))
    # The kernel must import this checkout's corn_drake (worktrees share one venv).
    monkeypatch.setenv("PYTHONPATH", str(REPO_ROOT))
    nb = nbformat.read(REPO_ROOT / "notebooks" / "05_perception.ipynb", as_version=4)
    NotebookClient(nb, timeout=300, kernel_name="python3",
                   resources={"metadata": {"path": str(REPO_ROOT)}}).execute()
    html = Path(tmp_path) / "05_perception.html"
    assert html.is_file() and html.stat().st_size > 10_000
    assert (Path(tmp_path) / "05_depth_images.png").is_file()
