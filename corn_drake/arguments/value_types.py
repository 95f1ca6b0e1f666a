"""argparse `type=` checks shared by every subcommand, so a bad count fails at parse time.

argparse turns an ArgumentTypeError into `corn-drake CMD: error: argument --NAME: MESSAGE`, so
the error names the argument without each command repeating it, and before any work starts.
"""

from __future__ import annotations

import argparse
import math
from typing import Callable


def _checked(kind: type, accept: Callable[[float], bool], what: str) -> Callable[[str], float]:
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        # float() takes 'nan' and 'inf', but no count, rate or duration here means them.
        if (kind is float and not math.isfinite(value)) or not accept(value):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return value

    return parse


positive_int = _checked(int, lambda v: v >= 1, "an integer >= 1")
nonnegative_int = _checked(int, lambda v: v >= 0, "an integer >= 0")
positive_float = _checked(float, lambda v: v > 0, "a number > 0")
finite_float = _checked(float, lambda v: True, "a finite number")
# A seed: numpy's legacy seeding, torch's and Ray's take 32-bit seeds; a larger one (or 1e23, not
# an integer) used to end a run with a traceback after its config.yaml was written. The same
# range as the configs' "seed" rule (config/bounds.SEED_LIMIT, 2**32).
seed_int = _checked(int, lambda v: 0 <= v < 2 ** 32, "an integer in [0, 2**32)")


def positive_int_list(text: str) -> list[int]:
    """'1,64,1024' -> [1, 64, 1024]; every item an integer >= 1."""
    try:
        return [positive_int(item.strip()) for item in text.split(",")]
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated integers >= 1, got {text!r}") from None
