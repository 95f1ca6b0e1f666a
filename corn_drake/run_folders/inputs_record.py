"""What a resumable output was made from, so a resume never mixes sources: the first run writes
OUT/inputs.json ({name: value}: the settings that decide what is written, and the sha256 of the
files it reads), and every later run into OUT compares its own and refuses, naming each input
that changed (a teacher trained further, a collection's settings, another proposing run).
Outputs from before the record are not checked (the first run that can records it)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from corn_drake.errors import InputError

RECORD = "inputs.json"


def file_sha256(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def refuse_changed_inputs(out: str | Path, inputs: dict, what: str) -> None:
    """An InputError naming each input that differs from those `out` recorded (nothing when it
    recorded none); `what` names the output's kind ("this collection")."""
    path = Path(out) / RECORD
    if not path.is_file():
        return
    inputs = json.loads(json.dumps(inputs))  # as it reads back
    recorded = json.loads(path.read_text())
    changed = sorted(k for k in set(recorded) | set(inputs) if recorded.get(k) != inputs.get(k))
    if changed:
        detail = "; ".join(f"{k}: {recorded.get(k)!r} then, {inputs.get(k)!r} now"
                           for k in changed)
        raise InputError(f"{out} holds {what} made from other inputs ({detail}); resuming would "
                         "mix them: give another output, or the inputs it was made from")


def record_inputs(out: str | Path, inputs: dict) -> None:
    """Writes `inputs` as what `out` was made from (kept when already recorded)."""
    from corn_drake.storage.atomic_files import write_json

    path = Path(out) / RECORD
    if not path.is_file():
        Path(out).mkdir(parents=True, exist_ok=True)
        write_json(path, inputs)


def check_inputs(out: str | Path, inputs: dict, what: str) -> None:
    """refuse_changed_inputs, then record_inputs."""
    refuse_changed_inputs(out, inputs, what)
    record_inputs(out, inputs)
