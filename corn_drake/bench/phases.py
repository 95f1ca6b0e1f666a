"""Exclusive wall time per named phase, for benchmarks that attribute a run's time to its parts.

A phase entered inside another is subtracted from the outer one, so the phases of one window
add up to the window's wall time exactly (the outer phase keeps what no inner phase claimed).
Time is only counted inside an open window (`open_window` .. `close_window`): one-time work
around the measured part (building, first reset, final checkpoint) stays out of the figures.

Instrumentation happens on instances (`wrap`, `TimedSimulator`), in the benchmark only: the
trainer, the env batch and the envs run their production code unchanged, and pay nothing when
no benchmark is timing them.
"""

from __future__ import annotations

import contextlib
import functools
import time
from collections import defaultdict
from typing import Callable


class PhaseTimer:
    WINDOW = "window"  # the window's own exclusive time: what no phase inside it claimed

    def __init__(self, clock: Callable[[], float] = time.perf_counter):
        self.clock = clock
        self.seconds: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self.window_seconds = 0.0  # total wall time of the closed windows
        self._stack: list[list] = []  # open phases: [name, start, time claimed by inner phases]

    @property
    def in_window(self) -> bool:
        return bool(self._stack) and self._stack[0][0] == self.WINDOW

    def _enter(self, name: str) -> None:
        self._stack.append([name, self.clock(), 0.0])

    def _exit(self) -> float:
        name, start, inner = self._stack.pop()
        elapsed = self.clock() - start
        self.seconds[name] += elapsed - inner
        self.calls[name] += 1
        if self._stack:
            self._stack[-1][2] += elapsed
        return elapsed

    def open_window(self) -> None:
        if self._stack:
            raise RuntimeError(f"open_window inside the open phase {self._stack[-1][0]!r}")
        self._enter(self.WINDOW)

    def close_window(self) -> None:
        if len(self._stack) != 1 or not self.in_window:
            raise RuntimeError("close_window: no window open, or a phase inside it still is")
        self.window_seconds += self._exit()

    @contextlib.contextmanager
    def phase(self, name: str):
        if not self.in_window:  # outside the measured part: run untimed
            yield
            return
        self._enter(name)
        try:
            yield
        finally:
            self._exit()

    def wrap(self, obj, method: str, name: str) -> None:
        """Times every call of `obj.method` as phase `name` (an instance attribute shadowing the
        class's method, so only this object is instrumented)."""
        original = getattr(obj, method)

        @functools.wraps(original)
        def timed(*args, **kwargs):
            with self.phase(name):
                return original(*args, **kwargs)

        setattr(obj, method, timed)


class TimedSimulator:
    """A Drake Simulator whose AdvanceTo is timed as phase `name`; everything else passes
    through. (pybind objects take no new attributes, so the env's reference is replaced.)"""

    def __init__(self, simulator, timer: PhaseTimer, name: str):
        self._simulator, self._timer, self._name = simulator, timer, name

    def AdvanceTo(self, boundary_time):
        with self._timer.phase(self._name):
            return self._simulator.AdvanceTo(boundary_time)

    def __getattr__(self, attr):
        return getattr(self._simulator, attr)


def time_simulator(env, timer: PhaseTimer, name: str) -> None:
    """Times `env.simulator.AdvanceTo` as phase `name` (once per env, however often called)."""
    if not isinstance(env.simulator, TimedSimulator):
        env.simulator = TimedSimulator(env.simulator, timer, name)
