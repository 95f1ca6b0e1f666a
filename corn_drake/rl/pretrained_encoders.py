"""Which encoder each policy variant gets (corn_drake/rl/policy_kinds.py): corn — the frozen
contact-pretrained patch encoder; p2v-lite / rot — the frozen patch encoder pretrained on that
pretext task (pretext/); pn — the frozen contact-pretrained PointNet; e2e — a fresh patch encoder
trained by PPO; state — none.
Each is a NormalizedEncoder: the network with the input normalisation it was (or is) trained
with, so a policy normalises its inputs as its encoder expects."""

from __future__ import annotations

import math
from pathlib import Path

from corn_drake.errors import InputError
from corn_drake.nn.encoders.encoder_files import (NormalizedEncoder, load_frozen_encoder,
                                                  make_policy_encoder)
from corn_drake.rl.policy_kinds import ENCODER_KIND

# A frozen encoder must have learned its pretext task before a policy is trained on it: a
# PointNet with 367 pretraining steps (patch F1 0.000, all "no contact") once made every `pn`
# result a measurement of an untrained encoder. 0.8 patch F1 is the bar the contact encoders are
# held to; CORN's encoder reaches ~0.9.
MIN_CONTACT_F1 = 0.8

# The pretext encoders' bar (p2v-lite, rot): their pretraining record's skill, 1 - loss / the
# loss of the best prediction that ignores the input (pretraining/pretext.py), on unseen objects
# when measured, else held-out placements. 0 is an encoder whose output says nothing its task
# can use, and a fresh one scores <= 0 (-0.06 for both tasks on the 80-object library).
# Measured there on one CPU: P2V-lite reached 0.46 after 100 steps of 32 clouds and 0.55 after
# 200; ROT stayed at -0.06 after 100-150 steps, so a short ROT run is refused. A loss alone
# cannot be the bar: P2V-lite's targets move with its teacher.
MIN_PRETEXT_SKILL = 0.2

CONTACT_KINDS = ("corn", "pointnet")


def _recorded(pretraining: dict | None, keys: tuple[str, ...]) -> float | None:
    """The first finite value of `keys` in a pretraining record."""
    for key in keys:
        value = (pretraining or {}).get(key)
        if value is not None and math.isfinite(value):
            return float(value)
    return None


def contact_f1(pretraining: dict | None) -> float | None:
    """The encoder's recorded patch F1: on unseen objects when measured, else held-out poses."""
    return _recorded(pretraining, ("unseen_patch_f1", "heldout_patch_f1"))


def pretext_skill(pretraining: dict | None) -> float | None:
    """A pretext encoder's recorded skill: on unseen objects when measured, else held-out
    placements of the training objects."""
    return _recorded(pretraining, ("unseen_pretext_skill", "heldout_pretext_skill"))


def check_pretrained(encoder, checkpoint, allow_weak: bool) -> None:
    """Refuses an encoder whose pretraining record is missing or below its kind's bar
    (MIN_CONTACT_F1 for contact encoders, MIN_PRETEXT_SKILL for pretext ones), unless
    `allow_weak` (smoke tests, the demo's tiny pretraining): then it only warns."""
    import sys

    record = getattr(encoder, "pretraining", None)
    if getattr(encoder, "kind", "corn") in CONTACT_KINDS:
        value, bar, what = contact_f1(record), MIN_CONTACT_F1, "contact patch F1"
    else:
        value, bar, what = pretext_skill(record), MIN_PRETEXT_SKILL, f"{encoder.kind} pretext skill"
    if value is not None and value >= bar:
        return
    why = ("records no pretraining metrics" if value is None
           else f"reached {what} {value:.3f} < {bar} in pretraining")
    if not allow_weak:
        raise InputError(f"--encoder {checkpoint} {why}: pretrain it longer, or pass "
                         "--allow-weak-encoder to train on it anyway")
    if _first_warning(checkpoint, why):
        print(f"warning: --encoder {checkpoint} {why}; used because weak encoders are allowed "
              "(--allow-weak-encoder, or allow_weak_encoder in the run's config)", file=sys.stderr)


# The weak encoders already warned about in this process, by content: a command that loads the
# same encoder again (a run folder's copy of it included) says so once.
_warned: set[tuple[str, str]] = set()


def _first_warning(checkpoint, why: str) -> bool:
    import hashlib

    try:
        key = (hashlib.sha256(Path(checkpoint).read_bytes()).hexdigest(), why)
    except (OSError, TypeError):
        key = (str(checkpoint), why)
    if key in _warned:
        return False
    _warned.add(key)
    return True


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
