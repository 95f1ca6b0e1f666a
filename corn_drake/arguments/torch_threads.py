"""`--torch-threads`, the argument of the commands that run torch: its parser, its help and its
one default. What each setting measured on this project's machine is in nn/threads.py, which
applies it.
"""

from __future__ import annotations

import argparse

from corn_drake.arguments.value_types import positive_int
from corn_drake.nn.threads import SMALL_MACHINE_CPUS, auto_torch_threads

# One default for every command. "auto" is torch's own count on a machine with more than
# SMALL_MACHINE_CPUS CPUs, and 1 thread on a small one, where it costs a quiet `corn` training
# run up to 12 % but saves it from running 4.5x slower when another busy process shares the
# core (nn/threads.py, the results page); evaluation runs level with 1 or 2 threads.
DEFAULT = "auto"


def torch_threads_arg(text: str) -> int | None:
    """argparse type of --torch-threads: 'torch' (torch's own count: None), 'auto'
    (auto_torch_threads) or an integer >= 1."""
    if text == "torch":
        return None
    if text == "auto":
        return auto_torch_threads()
    try:
        return positive_int(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"expected 'torch', 'auto' or an integer >= 1, got {text!r}") from None


def add_torch_threads_argument(parser, what: str) -> None:
    """--torch-threads for a command that runs `what`."""
    parser.add_argument("--torch-threads", type=torch_threads_arg, default=DEFAULT,
                        help=f"torch intra-op threads for {what}: auto (1 on a machine with <= "
                             f"{SMALL_MACHINE_CPUS} usable CPUs, where a second thread made "
                             "training 4.5x slower beside another busy process and a quiet "
                             "one up to 12 %% faster; torch's own count on a larger machine), "
                             "torch "
                             "(torch's own count) or a count (measurements: "
                             "corn_drake/nn/threads.py)")
