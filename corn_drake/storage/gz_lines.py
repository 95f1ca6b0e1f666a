"""JSON lines kept gzipped, one gzip member per line: the expert's labels files (~80 KB of JSON
an episode, a fifth of that gzipped) stay appendable a line at a time, and any gzip reader
(`zcat`, Python's gzip) reads the members as one text.

A line is appended as one complete member and flushed to disk, so a kill can cut only the last
member short; `read_lines` keeps every whole member before it and says where they end, and
`cut_after` trims a cut member away before the file is appended to again (a resume). Plain
JSON-lines files (written before the labels were gzipped) read the same way.
"""

from __future__ import annotations

import gzip
import json
import os
import zlib
from pathlib import Path

from corn_drake.storage.atomic_files import atomic_path

GZIP_MAGIC = b"\x1f\x8b"


def _member(line: str) -> bytes:
    # mtime 0: the same line gives the same bytes, so a rewritten file diffs as unchanged.
    return gzip.compress((line + "\n").encode(), mtime=0)


def append_line(path: Path, record: dict) -> None:
    """Appends `record` to `path` as one whole gzip member, on disk when this returns."""
    with open(path, "ab") as f:
        f.write(_member(json.dumps(record)))
        f.flush()
        os.fsync(f.fileno())


def write_lines(path: Path, lines: list[str]) -> None:
    """`path` holding the text `lines` (JSON lines), a member each, written atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(b"".join(_member(line) for line in lines))


def read_text(path: Path) -> tuple[str, int | None]:
    """(the text of `path`, gzipped or plain; the byte length of its whole members when a kill
    cut the last one short, else None). The text of a gzipped file is that of its whole
    members, so a file gzipped from a plain one reads as the plain one did. Plain files: a cut
    last line is the caller's to judge, as for any JSON-lines file."""
    data = path.read_bytes()
    if not data.startswith(GZIP_MAGIC):
        return data.decode(), None
    parts: list[bytes] = []
    at = 0
    while at < len(data):
        unzip = zlib.decompressobj(wbits=31)  # 31: a gzip header and trailer
        try:
            text = unzip.decompress(data[at:])
        except zlib.error:
            return b"".join(parts).decode(), at
        if not unzip.eof:
            return b"".join(parts).decode(), at
        parts.append(text)
        at = len(data) - len(unzip.unused_data)
    return b"".join(parts).decode(), None


def read_lines(path: Path) -> tuple[list[str], int | None]:
    """read_text's, split into lines."""
    text, whole = read_text(path)
    return text.splitlines(), whole


def cut_after(path: Path, whole: int) -> None:
    """Trims `path` to its first `whole` bytes (its whole members, read_lines' second value)."""
    with open(path, "r+b") as f:
        f.truncate(whole)
        f.flush()
        os.fsync(f.fileno())
