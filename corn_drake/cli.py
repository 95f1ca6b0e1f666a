"""`corn-drake <subcommand>`.

Each module in `corn_drake.commands` that defines `NAME`, `HELP`, `add_arguments(parser)` and
`run(args) -> int` is a subcommand; adding a file adds a command, so parallel work on different
commands never edits the same lines.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import signal
import sys

from corn_drake import commands
from corn_drake.arguments.help_format import DefaultsHelpFormatter
from corn_drake.errors import InputError, is_disk_full


def _command_modules():
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{commands.__name__}.{info.name}")
        if hasattr(module, "NAME") and hasattr(module, "run"):
            yield module


class OneLineParser(argparse.ArgumentParser):
    """argparse without the usage block on an error: one line naming the argument, exit 2, the
    same shape as an InputError's. Subcommand parsers inherit the class (add_subparsers uses
    the parent's type), so `corn-drake train --steps 0` reads `corn-drake train: error: ...`.
    Every parser made so (subcommands and `bench WHAT` included) shows its options' defaults in
    --help (arguments/help_format.py)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", DefaultsHelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="corn-drake", description=__doc__.splitlines()[0])
    parser.add_argument("--debug", action="store_true",
                        help="show the full traceback of an input error (or set CORN_DRAKE_DEBUG=1)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in _command_modules():
        p = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run, _prog=p.prog)
    return parser


class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived: the command stops where it is. A BaseException, like
    KeyboardInterrupt, so no `except Exception` on the way up swallows it."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    debug = args.debug or os.environ.get("CORN_DRAKE_DEBUG", "") not in ("", "0")
    interrupted: list[int] = []

    def on_signal(signum, frame):
        interrupted.append(signum)
        if signum == signal.SIGINT:  # as Python's own handler: code that waits for Ctrl-C
            raise KeyboardInterrupt  # (evaluate --keep-open) catches it
        raise Interrupted(signum)

    handlers = _install(on_signal)
    try:
        return int(args._run(args) or 0)
    except InputError as e:
        if debug:
            raise
        # One line, like argparse's own errors: the user's input is wrong, not the program.
        print(f"{args._prog}: error: {e}", file=sys.stderr)
        return 2
    except (Interrupted, KeyboardInterrupt, Exception) as e:
        # An interrupt, or what it caused on the way out (a Ray worker that got the same
        # SIGINT dies and ray.get raises): one line and 128 + the signal, as a shell reports it.
        signum = (e.signum if isinstance(e, Interrupted) else signal.SIGINT
                  if isinstance(e, KeyboardInterrupt) else interrupted[0] if interrupted else None)
        if signum is None and is_disk_full(e) and not debug:
            # A full disk is no bug: one line naming the file. Every write is atomic (temporary
            # file + rename), so what was written before it is complete and kept.
            where = f" writing {e.filename}" if getattr(e, "filename", None) else ""
            print(f"{args._prog}: error: no space left on the device{where}; the files written "
                  "before are complete and kept: free space there and run the same command "
                  "again to resume", file=sys.stderr)
            return 2
        if signum is None or debug:
            raise
        _stop_ray()
        name = signal.Signals(signum).name
        print(f"{args._prog}: interrupted ({name}): every checkpoint, shard, object or report "
              "written so far is complete and kept; run the same command again to resume",
              file=sys.stderr)
        return 128 + int(signum)
    finally:
        _restore(handlers)


def _stop_ray() -> None:
    """Shuts a Ray this process started down before the one line is printed, so its workers
    stop now and its core does not log about actors it loses at interpreter exit."""
    ray = sys.modules.get("ray")
    if ray is not None and ray.is_initialized():
        try:
            ray.shutdown()
        except Exception:  # noqa: BLE001 - the interrupt is what the user must hear about
            pass


def _install(handler) -> dict:
    """`handler` for SIGINT and SIGTERM (the main thread only: a notebook's worker thread
    cannot set handlers), returning the previous ones."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        return {}
    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        previous[sig] = signal.signal(sig, handler)
    return previous


def _restore(previous: dict) -> None:
    for sig, handler in previous.items():
        signal.signal(sig, handler)


if __name__ == "__main__":
    sys.exit(main())
