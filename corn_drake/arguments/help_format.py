"""How `corn-drake ... --help` shows an option's default.

argparse's ArgumentDefaultsHelpFormatter prints "(default: None)" for the many flags whose None
means "the run's recorded value" or "the config's": it says nothing. So the rule here is: a
default with a value (`--episodes 10`, `--torch-threads auto`) is appended by the formatter;
an unset one (None, "", an empty list) is explained in the help's own words ("default: the
run's task"), which tests/test_cli_help.py requires of every option.
"""

from __future__ import annotations

import argparse

UNSET = (None, "", [], ())


def has_shown_default(action: argparse.Action) -> bool:
    """Whether the formatter appends `(default: X)` to `action`'s help: an option that takes a
    value, is not required and defaults to a value (a switch's default is "off": no note)."""
    return (bool(action.option_strings) and action.nargs != 0 and not action.required
            and action.help not in (None, argparse.SUPPRESS)
            and action.default is not argparse.SUPPRESS
            and not any(action.default is u or action.default == u for u in UNSET if u is not None)
            and action.default is not None)


class DefaultsHelpFormatter(argparse.HelpFormatter):
    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if has_shown_default(action) and "%(default)" not in text:
            text += " (default: %(default)s)"
        return text
