"""torch's intra-op thread count: the count the commands use by default, and a block of code
run at a given count with the caller's count given back after."""

from __future__ import annotations

import argparse
import contextlib
import os

# "auto" resolves to ONE_CORE_THREADS where the process may use at most this many CPUs.
SMALL_MACHINE_CPUS = 2
ONE_CORE_THREADS = 1


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask, not the machine's count)."""
    return len(os.sched_getaffinity(0))


def auto_torch_threads(cpus: int | None = None) -> int | None:
    """The thread count `train`, `evaluate` and the trainer benchmarks use unless told: 1 on a
    machine with at most 2 usable CPUs, torch's own choice (None) on a larger one.

    Why 1 here: the project machines' 2 vCPUs give one core of throughput, and a second torch
    thread only helps while nothing else runs. Measured on one (bench train, corn, 32 envs,
    alternated): quiet, 1 and 2 threads trained at 308 / 294 and 305 / 316 steps/s; with one
    other busy process (a pretraining), 190 / 198 against 42 / 42, batch-32 inference taking
    18 ms per env step with 2 threads against 0.7 ms with 1 (the threads wait on each other)."""
    cpus = usable_cpus() if cpus is None else cpus
    return ONE_CORE_THREADS if cpus <= SMALL_MACHINE_CPUS else None


def torch_threads_arg(text: str) -> int | None:
    """argparse type of --torch-threads: 'auto' (auto_torch_threads) or an integer >= 1."""
    if text == "auto":
        return auto_torch_threads()
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected 'auto' or an integer >= 1, got {text!r}")
    return value


def add_torch_threads_argument(parser, what: str) -> None:
    """--torch-threads for a command that runs `what` (default: auto)."""
    parser.add_argument("--torch-threads", type=torch_threads_arg, default="auto",
                        help=f"torch intra-op threads for {what}: auto (default: 1 on a machine "
                             f"with <= {SMALL_MACHINE_CPUS} usable CPUs, torch's own choice on a "
                             "larger one) or a count")


@contextlib.contextmanager
def torch_threads(count: int | None):
    """torch.set_num_threads(count) inside (None: torch's own choice), the caller's count back
    after: the setting is process-wide, and a caller in the same process (a notebook, the
    tests) keeps its own."""
    import torch  # here, not at the top: the argparse helpers above are read by every command

    before = torch.get_num_threads()
    if count is not None:
        torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(before)
