"""corn_drake: CORN (ICLR 2024) rebuilt as a Drake systems-framework project."""

from pathlib import Path

__version__ = "0.1.0"

# Repository root (the folder holding models/ and diagrams/); the package is installed editable.
REPO_ROOT = Path(__file__).resolve().parent.parent
MODELS_DIR = REPO_ROOT / "models"
DIAGRAMS_DIR = REPO_ROOT / "diagrams"
