"""Ends the local Ray processes a driver started once that driver is gone, kill -9 included.

Ray ties its direct children (gcs_server, raylet, ...) to the driver, but the raylet's own
children, the DashboardAgent and RuntimeEnvAgent, outlive a killed driver by a minute or more
(they wait on the dead GCS to report the raylet's death). `init_ray` starts this script as a
separate process with the PIDs of the processes ray.init started; it watches them and their
descendants and, when the driver dies (its end of our stdin pipe closes) or Ray has shut down
(every root is gone), kills every one it saw that is still running, then exits.

Run as a script (not `-m`) so it needs nothing but psutil: `python ray_reaper.py PID...`.
"""

from __future__ import annotations

import selectors
import signal
import sys

import psutil

# Agents appear within seconds of ray.init; watch closely then, and cheaply for the long run.
FAST_POLL_S, FAST_PERIOD_S, SLOW_POLL_S = 0.2, 30.0, 2.0


def _alive(process: psutil.Process) -> bool:
    try:
        return process.is_running() and process.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def _record_descendants(roots: list[psutil.Process], seen: dict[int, psutil.Process]) -> None:
    for root in roots:
        try:
            for child in root.children(recursive=True):
                seen.setdefault(child.pid, child)
        except psutil.Error:
            continue


def _kill_all(seen: dict[int, psutil.Process]) -> None:
    for process in seen.values():
        try:
            # psutil refuses to signal a PID reused by another process (it compares start times).
            process.kill()
        except psutil.Error:
            continue


def watch(roots: list[psutil.Process]) -> None:
    """Blocks until the driver (our stdin's writer) or every root is gone, then kills all."""
    seen = {p.pid: p for p in roots}
    selector = selectors.DefaultSelector()
    selector.register(sys.stdin, selectors.EVENT_READ)
    waited = 0.0
    while True:
        _record_descendants(roots, seen)
        poll = FAST_POLL_S if waited < FAST_PERIOD_S else SLOW_POLL_S
        if selector.select(timeout=poll):  # readable means EOF: the driver never writes
            break
        waited += poll
        if not any(_alive(r) for r in roots):
            break
    _kill_all(seen)


def main(argv: list[str]) -> int:
    # The driver's Ctrl-C or terminal hang-up must not end the reaper before it has cleaned up.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    roots = []
    for pid in argv:
        try:
            roots.append(psutil.Process(int(pid)))
        except psutil.Error:
            continue
    if roots:
        watch(roots)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
