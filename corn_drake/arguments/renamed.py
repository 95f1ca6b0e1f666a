"""Flags that were renamed, so one thing has one name across the CLI (issue 36): the old
spelling stays a hidden option that refuses with a one-line error naming the new one, because a
script written against the old name should fail loudly, not run with the flag ignored or, worse,
taken as a prefix of another flag.
"""

from __future__ import annotations

import argparse


class _Renamed(argparse.Action):
    def __init__(self, option_strings, dest, new: str = "", why: str = "", **kwargs):
        # nargs "?": `--objects 14` and a bare `--objects` both reach the refusal below.
        super().__init__(option_strings, dest, nargs="?", default=argparse.SUPPRESS,
                         help=argparse.SUPPRESS, **kwargs)
        self.new, self.why = new, why

    def __call__(self, parser, namespace, values, option_string=None):
        parser.error(f"{option_string} is now {self.new}{self.why}")


def add_renamed(parser, old: str, new: str, why: str = "") -> None:
    """Refuse `old` (hidden from --help) with 'OLD is now NEW[why]' (`why` starts with ': ' or
    ' ')."""
    parser.add_argument(old, action=_Renamed, new=new, why=why, dest=f"_renamed_{old.lstrip('-')}")
