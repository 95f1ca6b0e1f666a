"""`corn-drake <subcommand>`.

Each module in `corn_drake.commands` that defines `NAME`, `HELP`, `add_arguments(parser)` and
`run(args) -> int` is a subcommand; adding a file adds a command, so parallel work on different
commands never edits the same lines.
"""

from __future__ import annotations

import argparse
import difflib
import importlib
import os
import pkgutil
import re
import signal
import sys

from corn_drake import __version__, commands
from corn_drake.arguments.help_format import DefaultsHelpFormatter
from corn_drake.errors import InputError, is_disk_full


def _command_modules():
    """Every module of commands/ and its role folders (data/, learning/, reporting/) that
    defines a subcommand (NAME and run), in the order of their names."""
    found = pkgutil.walk_packages(commands.__path__, f"{commands.__name__}.")
    for info in sorted(found, key=lambda m: m.name.rsplit(".", 1)[-1]):
        if info.ispkg or info.name.rsplit(".", 1)[-1].startswith("_"):
            continue
        module = importlib.import_module(info.name)
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
        self.exit(2, f"{self.prog}: error: {message}{_choice_hint(message)} "
                     f"(see {self.prog} --help)\n")


def _closest(word: str, candidates) -> str | None:
    """The candidate `word` most likely misspells (difflib), or None."""
    found = difflib.get_close_matches(word, list(candidates), n=1, cutoff=0.6)
    return found[0] if found else None


def _choice_hint(message: str) -> str:
    """'; did you mean X?' for argparse's "invalid choice: 'x' (choose from 'a', 'b')" (a
    mistyped command, policy or split), else ''."""
    m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
    if not m:
        return ""
    guess = _closest(m.group(1), re.findall(r"'([^']*)'", m.group(2)))
    return f"; did you mean {guess}?" if guess else ""


def _innermost(parser: argparse.ArgumentParser, args) -> argparse.ArgumentParser:
    """The (sub)parser that parsed the last chosen command word: `corn-drake train` or
    `corn-drake bench sim`."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            chosen = action.choices.get(getattr(args, action.dest, None) or "")
            if chosen is not None:
                return _innermost(chosen, args)
    return parser


def _flag_hint(parser: argparse.ArgumentParser, unknown: list[str]) -> str:
    """'; did you mean --steps?' for the first unknown argument that looks like a flag and is
    close to one `parser` shows in its --help (renamed, hidden spellings left out)."""
    flags = [s for a in parser._actions if a.help != argparse.SUPPRESS
             for s in a.option_strings if s.startswith("--")]
    for word in unknown:
        if word.startswith("--"):
            guess = _closest(word.split("=", 1)[0], flags)
            if guess:
                return f"; did you mean {guess}?"
    return ""


def version_line() -> str:
    """`corn-drake --version`: the package's version, the Python running it and the versions of
    drake and torch installed for that Python (read from their metadata, nothing imported)."""
    from importlib import metadata

    def installed(dist: str) -> str:
        try:
            return metadata.version(dist)
        except metadata.PackageNotFoundError:
            return "not installed"

    return (f"corn-drake {__version__} (Python {sys.version.split()[0]}, drake "
            f"{installed('drake')}, torch {installed('torch')})")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="corn-drake", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=version_line(),
                        help="print the version (and this Python's drake and torch) and exit")
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


# The imports a command needs that a Python without the project installed lacks: found (not
# imported) before a command runs, so such a Python prints one line instead of a traceback.
HEAVY_MODULES = ("pydrake", "torch")
# The distributions behind the modules a dependency-less Python fails to import (top-level name).
DEPENDENCY_MODULES = {"pydrake", "torch", "numpy", "scipy", "open3d", "trimesh", "manifold3d",
                      "coacd", "gymnasium", "ray", "psutil", "tensorboard", "tqdm", "matplotlib",
                      "yaml"}


def missing_dependency_line(module: str) -> str:
    """One line for a Python that lacks `module` (a dependency): which Python, and how to run
    the CLI with the project's environment instead."""
    from corn_drake.package_data import CHECKOUT_ROOT

    venv = CHECKOUT_ROOT / ".venv" / "bin"  # a source checkout's `make install` venv
    how = (f"activate the project's venv (source {venv}/activate) or run {venv}/corn-drake"
           if (venv / "python").exists() else
           "install the project into this Python (pip install corn-drake, or `make install` / "
           "pip install -e . in its checkout) or activate the environment it is installed in")
    return (f"corn-drake: error: this Python ({sys.executable}) has no {module!r} module, which "
            f"corn-drake needs: {how}")


def _check_dependencies() -> str | None:
    """The first of HEAVY_MODULES this Python cannot import, or None."""
    import importlib.util

    for name in HEAVY_MODULES:
        try:
            if importlib.util.find_spec(name) is None:
                return name
        except (ImportError, ValueError):
            return name
    return None


def parse(argv: list[str] | None = None):
    """The parsed arguments; an unknown argument is refused by the (sub)command's parser, naming
    the closest flag that command has ("did you mean")."""
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    if unknown:
        inner = _innermost(parser, args)
        inner.error(f"unrecognized arguments: {' '.join(unknown)}"
                    f"{_flag_hint(inner, unknown) or _flag_hint(parser, unknown)}")
    return args


def main(argv: list[str] | None = None) -> int:
    try:
        args = parse(argv)
    except ModuleNotFoundError as e:  # a command module's import, in a Python without the deps
        if (e.name or "").split(".")[0] not in DEPENDENCY_MODULES:
            raise
        print(missing_dependency_line(e.name), file=sys.stderr)
        return 1
    missing = _check_dependencies()
    if missing is not None:
        print(missing_dependency_line(missing), file=sys.stderr)
        return 1
    debug = args.debug or os.environ.get("CORN_DRAKE_DEBUG", "") not in ("", "0")
    interrupted: list[int] = []

    def on_signal(signum, frame):
        interrupted.append(signum)
        if signum == signal.SIGINT:  # as Python's own handler: code that waits for Ctrl-C
            raise KeyboardInterrupt  # (evaluate --keep-open) catches it
        raise Interrupted(signum)

    handlers = _install(on_signal)
    try:
        import_holding_signals(SWALLOWING_IMPORTS)
        code = int(args._run(args) or 0)
        stops = [sig for sig in interrupted if sig != signal.SIGINT]
        if stops:  # a library swallowed the Interrupted: the stop is still reported (a
            raise Interrupted(stops[0])  # KeyboardInterrupt may be caught on purpose: --keep-open)
        return code
    except InputError as e:
        if debug:
            raise
        # One line, like argparse's own errors: the user's input is wrong, not the program.
        print(f"{args._prog}: error: {e}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as e:
        if debug or (e.name or "").split(".")[0] not in DEPENDENCY_MODULES:
            raise
        print(missing_dependency_line(e.name), file=sys.stderr)
        return 1
    except (Interrupted, KeyboardInterrupt, Exception) as e:
        # An interrupt, or what it caused on the way out (a Ray worker that got the same
        # SIGINT dies and ray.get raises): one line and 128 + the signal, as a shell reports it.
        signum = (e.signum if isinstance(e, Interrupted) else signal.SIGINT
                  if isinstance(e, KeyboardInterrupt) else interrupted[0] if interrupted else None)
        if signum is None and is_disk_full(e) and not debug:
            # A full disk is no bug: one line naming the file. Every write is atomic (temporary
            # file + rename), so what was written before it is complete and kept.
            # A copy that fills the disk names its source first and its target second
            # (shutil): the disk that is full is the target's.
            target = getattr(e, "filename2", None) or getattr(e, "filename", None)
            where = f" writing {target}" if target else ""
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


# Libraries whose import catches BaseException around its optional imports (trimesh wraps each
# in `except BaseException`): an Interrupted raised there was swallowed, and a SIGTERM 2.4 s
# into `train --policy primitive` let the run train on and exit 0. They are imported before the
# command runs, with the signals held, so a signal meanwhile is delivered after.
SWALLOWING_IMPORTS = ("trimesh",)


def import_holding_signals(names) -> None:
    """Imports `names` with SIGINT and SIGTERM held (corn_drake/signals.py); one that arrives
    meanwhile is delivered to the installed handler once they are imported."""
    import importlib

    from corn_drake.signals import held_signals

    with held_signals():
        for name in names:
            importlib.import_module(name)


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
