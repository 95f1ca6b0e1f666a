"""Waiting for a condition in tests without asserting how long it takes.

A busy machine (another test run, a training job beside it) may take many times longer than a
quiet one, so a test waits for what it needs and asserts only the order of events. The cap is
there only so that a hung process fails the test instead of blocking the suite; it is far
beyond any time the event takes on a loaded machine.
"""

import time

HANG_GUARD_S = 600.0


def wait_until(predicate, what: str, cap_s: float = HANG_GUARD_S, poll_s: float = 0.2) -> None:
    """Returns once `predicate()` is true; fails the test, naming `what`, after `cap_s`."""
    # monotonic: a clock change while waiting must not cut the wait short or stretch it.
    give_up = time.monotonic() + cap_s
    while not predicate():
        assert time.monotonic() < give_up, f"still waiting for {what} after {cap_s:.0f} s (hung?)"
        time.sleep(poll_s)
