"""Which encoder each policy variant gets: corn — the frozen pretrained patch encoder; pn — the
frozen pretrained PointNet; e2e — a fresh patch encoder trained by PPO; state — none.
Each is a NormalizedEncoder: the network with the input normalisation it was (or is) trained
with, so a policy normalises its inputs as its encoder expects."""

from __future__ import annotations

from pathlib import Path

from corn_drake.errors import InputError
from corn_drake.nn.encoder_io import NormalizedEncoder, load_frozen_encoder, make_policy_encoder

ENCODER_KIND = {"corn": "corn", "e2e": "corn", "pn": "pointnet"}

# A frozen encoder must have learned its pretext task before a policy is trained on it: a
# PointNet with 367 pretraining steps (patch F1 0.000, all "no contact") once made every `pn`
# result a measurement of an untrained encoder. 0.8 patch F1 is the bar the baselines are held
# to; CORN's encoder reaches ~0.9.
MIN_CONTACT_F1 = 0.8


def contact_f1(pretraining: dict | None) -> float | None:
    """The encoder's recorded patch F1: on unseen objects when measured, else held-out poses."""
    import math

    for key in ("unseen_patch_f1", "heldout_patch_f1"):
        value = (pretraining or {}).get(key)
        if value is not None and math.isfinite(value):
            return float(value)
    return None


def check_pretrained(encoder, checkpoint, allow_weak: bool) -> None:
    """Refuses an encoder whose pretraining record is missing or below MIN_CONTACT_F1, unless
    `allow_weak` (smoke tests, the demo's tiny pretraining): then it only warns."""
    import sys

    f1 = contact_f1(getattr(encoder, "pretraining", None))
    if f1 is not None and f1 >= MIN_CONTACT_F1:
        return
    why = ("records no pretraining metrics" if f1 is None
           else f"reached contact patch F1 {f1:.3f} < {MIN_CONTACT_F1} in pretraining")
    if not allow_weak:
        raise InputError(f"--encoder {checkpoint} {why}: pretrain it longer, or pass "
                         "--allow-weak-encoder to train on it anyway")
    print(f"warning: --encoder {checkpoint} {why}; used because --allow-weak-encoder is set",
          file=sys.stderr)


def load_encoder(policy: str, checkpoint: str | Path | None,
                 allow_weak: bool = False) -> NormalizedEncoder | None:
    if policy == "state":
        return None
    if policy == "e2e":
        return make_policy_encoder("corn")
    if not checkpoint:
        raise InputError(f"policy {policy!r} needs --encoder CHECKPOINT (a pretrained encoder)")
    encoder = load_frozen_encoder(checkpoint)
    expected = ENCODER_KIND[policy]
    if encoder.kind != expected:
        raise InputError(f"policy {policy!r} needs a {expected} encoder, {checkpoint} holds a "
                         f"{encoder.kind} one")
    check_pretrained(encoder, checkpoint, allow_weak)
    return encoder


def make_encoder(policy: str) -> NormalizedEncoder | None:
    """A randomly initialised encoder of the kind `policy` uses (for e2e and for benchmarks)."""
    return None if policy == "state" else make_policy_encoder(ENCODER_KIND[policy])
