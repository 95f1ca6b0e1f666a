"""Runs of every kind as one thing: LoadedRun (loaded.py) and the registry of run kinds
(kinds.py) that `evaluate`, `gallery`, `ship`, `distill`, `label` and `demo` load runs through."""
