"""torch's intra-op thread count: what `--torch-threads auto` resolves to, and a block of code run
at a given count with the caller's count given back after (the argument itself:
arguments/torch_threads.py).

Measured on a project machine (2 vCPUs giving one core of throughput), the results page:
- training, quiet: torch's 2 threads beat 1 by 5 % for `corn` and 20-50 % for `e2e` and `pn`,
  whose PPO updates are heavy (bench policies, the runs' PPO settings, 5 timed updates);
- training beside one other busy process: 2 threads wait on each other and train 4.5x slower
  than 1 (bench train corn: 42 against 190-198 steps/s);
- evaluation (one observation at a time): 1 and 2 threads level quiet (40 episodes in 23-26 s).
So every command defaults to "auto" (one default, issue 36): one thread on such a machine, which
costs a quiet `corn` run up to 12 % and spares it the 4.5x loss when anything runs beside it;
torch's own count on a larger machine.
"""

from __future__ import annotations

import contextlib
import os


# "auto" resolves to one thread where the process may use at most this many CPUs.
SMALL_MACHINE_CPUS = 2


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask, not the machine's count)."""
    return len(os.sched_getaffinity(0))


def auto_torch_threads(cpus: int | None = None) -> int | None:
    """"auto": 1 on a machine with at most SMALL_MACHINE_CPUS usable CPUs, torch's own count
    (None) on a larger one."""
    cpus = usable_cpus() if cpus is None else cpus
    return 1 if cpus <= SMALL_MACHINE_CPUS else None


@contextlib.contextmanager
def torch_threads(count: int | None):
    """torch.set_num_threads(count) inside (None: torch's own choice), the caller's count back
    after: the setting is process-wide, and a caller in the same process (a notebook, the
    tests) keeps its own."""
    import torch  # here, not at the top: arguments/torch_threads.py imports this module for every command

    before = torch.get_num_threads()
    if count is not None:
        torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(before)
