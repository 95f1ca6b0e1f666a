"""Every `--help` shows each option's default and every flag has help (issue 36); old spellings
of renamed flags are refused naming the new one. The options are read from the parsers
themselves, so a flag added later is checked too."""

import argparse
import re

import pytest

from corn_drake.arguments.help_format import has_shown_default
from corn_drake.cli import build_parser, main


def _parsers(parser, path=()):
    """(argv prefix, parser) of the top level, every subcommand and every `bench WHAT`."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, path + (name,))


PARSERS = list(_parsers(build_parser()))


def _options(parser):
    return [a for a in parser._actions if a.option_strings and a.help != argparse.SUPPRESS
            and not isinstance(a, argparse._HelpAction)]


def _flat(text: str) -> str:
    return "".join(text.split())  # --help wraps lines at spaces and after hyphens


def test_every_subcommand_and_bench_is_checked():
    names = {" ".join(path) for path, _ in PARSERS}
    assert {"train", "evaluate", "objects", "demo", "bench sim", "bench train"} <= names
    assert len(names) > 20


@pytest.mark.parametrize("path", [path for path, _ in PARSERS], ids=" ".join)
def test_help_shows_every_options_default(path, capsys):
    parser = dict(PARSERS)[path]
    with pytest.raises(SystemExit) as stop:
        main([*path, "--help"])
    assert stop.value.code == 0
    shown = _flat(capsys.readouterr().out)
    for action in _options(parser):
        flag = action.option_strings[-1]
        assert action.help, f"{' '.join(path)} {flag} has no help"
        if action.nargs == 0 or action.required:
            continue  # a switch is off unless given; a required option has no default
        text = _flat(action.help % {**vars(action), "default": action.default})
        if has_shown_default(action):
            default = action.default
            if isinstance(default, (list, tuple)):
                default = ",".join(map(str, default))
            assert _flat(f"(default: {default})") in shown, f"{' '.join(path)} {flag}"
            assert text in shown, f"{' '.join(path)} {flag}"
        else:
            # Unset (None, "", []): "None" says nothing; the help says what it means instead.
            assert re.search(r"\bdefault\b", action.help), f"{' '.join(path)} {flag}: {text!r}"
            assert "(default:None)" not in shown


@pytest.mark.parametrize("argv, old, new", [
    (["demo", "--objects", "3"], "--objects", "--num-objects"),
    (["bench", "sim", "--report", "r.json", "--config", "push"], "--config", "--task"),
    (["bench", "sim", "--report", "r.json", "--envs", "8"], "--envs", "--envs-per-worker"),
    (["bench", "train", "--report", "r.json", "--envs", "8"], "--envs", "--envs-per-worker"),
    (["bench", "policies", "--report", "r.json", "--envs", "8"], "--envs", "--envs-per-worker"),
])
def test_an_old_spelling_is_refused_naming_the_new_one(argv, old, new, capsys):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == 2 and len(err) == 1
    assert f"error: {old} is now {new}" in err[0]


def test_one_torch_threads_default_everywhere():
    defaults = {" ".join(path): a.default for path, p in PARSERS for a in _options(p)
                if "--torch-threads" in a.option_strings}
    assert {"train", "evaluate", "bench policies", "bench train"} <= set(defaults)
    assert set(defaults.values()) == {"auto"}, defaults


def test_no_seed_takes_a_negative_number():
    seeds = [(path, a) for path, p in PARSERS for a in _options(p) if "--seed" in a.option_strings]
    assert len(seeds) > 8
    for path, action in seeds:
        with pytest.raises(argparse.ArgumentTypeError):
            action.type("-1")
