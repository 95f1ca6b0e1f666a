"""SIGINT and SIGTERM held while code runs that must not see them: the one mechanism the CLI
(around imports of libraries that swallow BaseException) and Ray's start-up
(rl/workers/ray_workers.py) share.

Why both parts: a Python handler always runs in the main thread, whichever thread the kernel
hands the signal to, so blocking the signal in the main thread alone does not keep the handler
out of the held code once other threads exist (measured: a test suite's leftover threads took
it). Inside `held_signals()` the handlers are a recorder (nothing raises inside), and the main
thread blocks both signals in the kernel, so threads started meanwhile (Ray's) inherit the
block and native handlers installed meanwhile never see them. On the way out the previous
handlers come back, the block is lifted, and a signal recorded or pending meanwhile is raised
again: it ends the command as it would have a moment later.
"""

from __future__ import annotations

import contextlib
import signal
import threading

HELD = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def held_signals():
    if threading.current_thread() is not threading.main_thread():
        yield  # signal handlers belong to the main thread (a notebook's worker thread: as is)
        return
    held: list[int] = []
    handlers = {sig: signal.getsignal(sig) for sig in HELD}
    for sig in HELD:
        signal.signal(sig, lambda signum, frame: held.append(signum))
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, set(HELD))
    try:
        yield
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)  # a pending signal lands here
        if held:
            signal.raise_signal(held[0])
