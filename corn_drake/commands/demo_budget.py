"""The demo's time budget on the machine it runs on, as busy as it is now (issue 64).

Two short probes (a few forward and backward passes of the CORN encoder, the pretraining
stage's own work; an interpreted loop, for the simulator's and Python's stages) are timed at
the start and compared with the same probes on the project machine's quiet core: the ratios are
how much slower (or faster) each stage will run here now. Each stage's
seconds on that quiet core at the demo's default sizes (measured there, REFERENCE_STAGE_S)
scale with the sizes asked for. When contact data and pretraining would take the demo past
its budget, `--encoder auto` takes the shipped CORN encoder instead (6,000 pretraining steps)
and says so; the rest of the pipeline is the same.
"""

from __future__ import annotations

import time

# What a newcomer is promised: the demo ends in about ten minutes.
BUDGET_S = 600.0
# The probes' best-of-3 seconds on the project machine's quiet core, at the demo's one torch
# thread (`pace_probe()` with no other job running, 2026-11-29: torch 0.125-0.142, python
# 0.103-0.115 over four calls).
REFERENCE_PROBE_S = {"torch": 0.13, "python": 0.105}
# Seconds of each stage on that quiet core at the default sizes (`corn-drake demo --encoder
# pretrain`, one torch thread, 2026-11-29: 12.4 minutes in all; docs/results/demo/), the size
# each scales with, and the probe whose slowdown it shares (pretraining is torch's work, the
# rest mostly the simulator's and Python's). All five stages come to 12.4 minutes, past the
# budget even on a quiet core: `--encoder auto` takes the shipped encoder there too (9.2).
REFERENCE_STAGE_S = {"library": 119.0, "contact_data": 12.0, "pretraining": 182.0,
                     "training": 403.0, "evaluations": 27.0}
DEFAULT_SIZES = {"library": 14, "contact_data": 20_000, "pretraining": 600,
                 "training": 2_400, "evaluations": 20}
PROBE_OF = {"library": "python", "contact_data": "python", "pretraining": "torch",
            "training": "python", "evaluations": "python"}


def pace_probe() -> dict[str, float]:
    """Best of 3 timings of two fixed workloads (the same work on every machine): "torch", 4
    forward and backward passes of a CORN encoder on 32 clouds of 512 points, at the thread
    count in force; "python", 1,500,000 turns of an interpreted loop (~0.1 s: long enough
    that the host's jitter stays under a tenth)."""
    import torch

    from corn_drake.contract import HAND_STATE_DIM
    from corn_drake.nn.encoders.corn_encoder import CORNEncoder

    torch.manual_seed(0)
    encoder = CORNEncoder()
    clouds, hands = torch.randn(32, 512, 3), torch.randn(32, HAND_STATE_DIM)

    def torch_work():
        for _ in range(4):
            encoder.zero_grad()
            encoder(clouds, hands).square().mean().backward()

    def python_work():
        total = 0
        for i in range(1_500_000):
            total += (i * i) % 7

    best = {}
    for name, work in (("torch", torch_work), ("python", python_work)):
        times = []
        for _ in range(3):
            start = time.perf_counter()
            work()
            times.append(time.perf_counter() - start)
        best[name] = min(times)
    return best


def stage_seconds(sizes: dict, slowdowns: dict) -> dict:
    """Each stage's expected seconds here: its quiet reference, scaled by the size asked for
    and by how much slower its kind of work runs on this machine now."""
    return {stage: REFERENCE_STAGE_S[stage] * sizes[stage] / DEFAULT_SIZES[stage]
            * slowdowns[PROBE_OF[stage]] for stage in REFERENCE_STAGE_S}


def plan(sizes: dict, encoder: str, probe_s: dict | None = None) -> tuple[bool, dict, dict]:
    """(whether to take the shipped encoder, the expected seconds of every stage, the slowdowns
    by probe) for `encoder` "auto" / "pretrain" / "shipped"; `probe_s` the probes' times here
    (measured if None). Auto takes the shipped encoder when all the stages would not fit in
    BUDGET_S."""
    probe_s = pace_probe() if probe_s is None else probe_s
    slowdowns = {k: probe_s[k] / REFERENCE_PROBE_S[k] for k in REFERENCE_PROBE_S}
    expected = stage_seconds(sizes, slowdowns)
    shipped = encoder == "shipped" or (encoder == "auto" and sum(expected.values()) > BUDGET_S)
    return shipped, expected, slowdowns
