"""`--torch-threads`, the argument of the commands that run torch: its parser and its help.
What each setting measured on this project's machine is in nn/threads.py, which applies it.
"""

from __future__ import annotations

import argparse

from corn_drake.arguments.value_types import positive_int
from corn_drake.nn.threads import SMALL_MACHINE_CPUS, auto_torch_threads


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


def add_torch_threads_argument(parser, what: str, default: str = "torch") -> None:
    """--torch-threads for a command that runs `what`."""
    parser.add_argument("--torch-threads", type=torch_threads_arg, default=default,
                        help=f"torch intra-op threads for {what}: torch (torch's own count), "
                             f"auto (1 on a machine with <= {SMALL_MACHINE_CPUS} usable CPUs, "
                             f"torch's own on a larger one) or a count (default: {default}; "
                             "corn_drake/nn/threads.py gives the measurements)")
