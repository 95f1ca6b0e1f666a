"""Which encoder each policy variant gets: corn — the frozen pretrained patch encoder; pn — the
frozen pretrained PointNet; e2e — a fresh patch encoder trained by PPO; state — none."""

from __future__ import annotations

from pathlib import Path

from corn_drake.errors import InputError
from corn_drake.nn.encoder_io import load_frozen_encoder
from corn_drake.nn.encoder_io import make_encoder as make_fresh_encoder

ENCODER_KIND = {"corn": "corn", "e2e": "corn", "pn": "pointnet"}


def load_encoder(policy: str, checkpoint: str | Path | None):
    if policy == "state":
        return None
    if policy == "e2e":
        return make_fresh_encoder("corn")
    if not checkpoint:
        raise InputError(f"policy {policy!r} needs --encoder CHECKPOINT (a pretrained encoder)")
    encoder = load_frozen_encoder(checkpoint)
    expected = ENCODER_KIND[policy]
    actual = "corn" if hasattr(encoder, "tokenizer") else "pointnet"
    if actual != expected:
        raise InputError(f"policy {policy!r} needs a {expected} encoder, {checkpoint} holds a {actual} one")
    return encoder


def make_encoder(policy: str):
    """A randomly initialised encoder of the kind `policy` uses (for e2e and for benchmarks)."""
    return None if policy == "state" else make_fresh_encoder(ENCODER_KIND[policy])
