"""Building library objects side by side in worker processes (`corn-drake objects --workers N`).

Kept apart from assets/library.py, with nothing but the standard library and corn_drake.errors
imported at the top: a spawned worker imports this module (for its initializer) before anything
else, and the initializer must set the thread variables before numpy (OpenBLAS), CoACD (OpenMP)
or Drake load and size their thread pools.
"""

from __future__ import annotations

import functools
import os
import sys
from typing import Callable, Iterator, TypeVar

from corn_drake.errors import InputError

Item = TypeVar("Item")
Result = TypeVar("Result")

# Read once, when each library loads: numpy's OpenBLAS (or MKL) sizes its pool to the machine,
# CoACD runs its search under OpenMP (libgomp), Drake's Parallelism reads DRAKE_NUM_THREADS.
# Unset, N workers on an N-core machine would each start N threads and contend for the cores.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                    "DRAKE_NUM_THREADS")


class ObjectBuildError(InputError):
    """One object's build raised. An InputError so `corn-drake` prints it as one line naming
    the object (with the objects before it saved, the same command resumes there); the cause
    stays chained, and --debug shows its traceback, the worker's included."""


def single_threaded() -> None:
    """Pool initializer: one thread in each worker, so N workers use N cores and no more.

    Runs in a fresh spawned process, before the first object is unpickled (and with it numpy,
    CoACD and Drake imported), so the variables are read at their load. torch is not loaded by
    the build; were it ever, set_num_threads(1) covers a pool it sized already."""
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(1)


def in_plan_order(build: Callable[[Item], Result], todo: list[Item], workers: int,
                  name: Callable[[Item], str]) -> Iterator[Result]:
    """build(item) for each item of `todo`, yielded in `todo`'s order whatever order they finish
    in (so the manifest lists the objects as a serial build does), in `workers` processes.

    An item that raises ends the run with an ObjectBuildError naming it (name(item)); the
    results yielded before it are the caller's to keep. `build` must be picklable (a
    module-level function or a functools.partial of one) when workers > 1."""
    if workers <= 1 or len(todo) <= 1:
        for item in todo:
            yield _result(functools.partial(build, item), name(item))
        return
    yield from _pooled(build, todo, workers, name)


def _pooled(build, todo: list, workers: int, name) -> Iterator:
    """in_plan_order's process pool. Spawned, not forked: the parent has Drake (and, in the
    tests or a notebook, torch) loaded, and a fork of a process holding their threads can
    deadlock in the child; a spawned worker starts clean and imports what it needs."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    pool = ProcessPoolExecutor(max_workers=min(workers, len(todo)),
                               mp_context=multiprocessing.get_context("spawn"),
                               initializer=single_threaded)
    finished = False
    try:
        futures = [pool.submit(build, item) for item in todo]
        for item, future in zip(todo, futures):
            yield _result(future.result, name(item))
        finished = True
    finally:
        if not finished:
            _stop_workers(pool)
        pool.shutdown(wait=True, cancel_futures=True)


def _stop_workers(pool) -> None:
    """Ends the workers of a build that stops early (an error, Ctrl-C, SIGTERM) at once.

    Waiting would let each finish its running object and the one queued behind it (minutes),
    and nothing they make after the stop can be saved: the manifest takes objects in plan
    order, and those before the stop are saved already. A killed worker leaves at worst an
    object folder the manifest does not list and a temporary file of an atomic write, which
    the next build of that object clears (assets/library.py)."""
    terminate = getattr(pool, "terminate_workers", None)  # Python 3.14+
    if terminate is not None:
        terminate()
        return
    # Before 3.14 the executor keeps its processes here, and offers no public way to stop them.
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        if process.is_alive():
            process.terminate()


def _result(get: Callable[[], Result], what: str) -> Result:
    """get(), or an ObjectBuildError naming `what` and the first line of the error it raised
    (a dead worker included: BrokenProcessPool). Interrupts (BaseException) pass through."""
    try:
        return get()
    except Exception as e:  # noqa: BLE001 - any failure of one object is reported by its name
        lines = str(e).strip().splitlines()
        detail = f"{type(e).__name__}: {lines[0]}" if lines else type(e).__name__
        raise ObjectBuildError(f"object {what}: its build failed ({detail}); the objects before "
                               "it are saved and the same command resumes from it (--debug "
                               "shows the traceback)") from e
