"""How a rollout worker's process takes its core: pinned to one (`pin_workers`,
`bench cores --pin`), and torch held to one thread.

Unpinned, the kernel may run two busy workers on one core for a while and move a worker between
cores (losing its caches); on a many-core machine every lock-step update waits for the slowest
worker, so one such worker slows the whole update. Pinned, worker w runs on core w + 1 of the
cores its process may use (wrapping around), and core 0 of them is left to the learner and
Ray's own processes. The core is chosen inside the worker's process, from that process's own
affinity mask, so on a Ray cluster each node's workers take that node's cores.
Linux only (os.sched_setaffinity).
"""

from __future__ import annotations

import os


def usable_cores() -> set[int]:
    """The cores this process may run on; a clear error where the OS cannot say (not Linux)."""
    if not hasattr(os, "sched_setaffinity"):
        raise RuntimeError("pinning workers to cores needs Linux (os.sched_setaffinity)")
    return os.sched_getaffinity(0)


def worker_core(index: int, cpus: list[int] | None = None) -> int:
    """The core worker `index` runs on: the (index + 1)-th of `cpus` (default: the cores this
    process may use), wrapping around; with one core, that core."""
    if index < 0:
        raise ValueError(f"worker index must be >= 0, got {index}")
    cpus = sorted(usable_cores() if cpus is None else cpus)
    if not cpus:
        raise ValueError("no cores to pin to")
    return cpus[(index + 1) % len(cpus)]


def pin_process(core: int) -> None:
    """Runs this process (every thread it starts from now on) on `core` alone."""
    allowed = usable_cores()
    if core not in allowed:
        raise ValueError(f"core {core} is not one this process may use ({sorted(allowed)})")
    os.sched_setaffinity(0, {core})


def pin_worker(index: int | None) -> int | None:
    """Pins this process as worker `index` (None: leaves it as it is); the core, or None."""
    if index is None:
        return None
    core = worker_core(index)
    pin_process(core)
    return core


def take_worker_core(index: int | None) -> int | None:
    """A Ray rollout worker's first step (every kind: segments, primitives, lock-step envs):
    pinned as worker `index` (None: unpinned), and one torch thread, so its inference does not
    spread threads over the other workers' cores. The core, or None."""
    import torch

    core = pin_worker(index)
    torch.set_num_threads(1)
    return core
