"""Which encoder each policy variant gets (corn: frozen pretrained; e2e: fresh; state: none)."""

from __future__ import annotations

from pathlib import Path


def load_encoder(policy: str, checkpoint: str | Path | None):
    if policy == "state":
        return None
    if policy in ("corn", "pn"):
        if not checkpoint:
            raise ValueError(f"policy {policy!r} needs --encoder CHECKPOINT (a pretrained encoder)")
        if not Path(checkpoint).is_file():
            raise FileNotFoundError(f"encoder checkpoint not found: {checkpoint}")
    raise NotImplementedError(
        f"policy {policy!r}: the patch-transformer / PointNet encoders are not in this build yet")


def make_encoder(policy: str):
    """A randomly initialised encoder of the kind `policy` uses (for e2e and for benchmarks)."""
    if policy == "state":
        return None
    raise NotImplementedError(
        f"policy {policy!r}: the patch-transformer / PointNet encoders are not in this build yet")
