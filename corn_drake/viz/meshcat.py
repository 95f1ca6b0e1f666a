"""Meshcat helpers: a visualizer on a diagram and episodes saved as standalone HTML."""

from __future__ import annotations

from pathlib import Path

from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role

from corn_drake.storage.atomic_files import write_text


def add_meshcat_visualizer(builder, scene_graph, meshcat: Meshcat, publish_period: float = 0.05):
    params = MeshcatVisualizerParams(role=Role.kIllustration, publish_period=publish_period)
    return MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, params)


def save_recording(meshcat: Meshcat, path: str | Path) -> Path:
    """Publishes the recording and writes Meshcat's standalone HTML (opens in any browser)."""
    meshcat.PublishRecording()
    path = Path(path)
    write_text(path, meshcat.StaticHtml())
    return path
