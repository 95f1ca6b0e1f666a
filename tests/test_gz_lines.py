"""Labels files gzipped a line per member (storage/gz_lines.py): appended a line at a time, read
by any gzip reader, a member a kill cut short dropped and trimmed before the next append, and
the plain files older runs wrote read and gzipped on resume."""

from __future__ import annotations

import gzip
import json

import pytest

from corn_drake.errors import InputError
from corn_drake.rl.planner.labels import gzip_plain_labels, read_labels
from corn_drake.storage.gz_lines import append_line, cut_after, read_lines, read_text, write_lines

HEADER = {"settings": {"task": "full6d"}, "columns": ["source", "reward"]}


def _episode(k: int) -> dict:
    return {"episode": k, "object": f"box_{k}", "seed": k, "decisions": [{"labels": [["p", k]]}]}


def test_appended_lines_read_back_and_by_gzip_itself(tmp_path):
    path = tmp_path / "a.labels.jsonl.gz"
    for record in [HEADER, _episode(0), _episode(1)]:
        append_line(path, record)
    lines, whole = read_lines(path)
    assert whole is None and [json.loads(x) for x in lines] == [HEADER, _episode(0), _episode(1)]
    # Any gzip reader sees the members as one text (zcat, Python's gzip).
    with gzip.open(path, "rt") as f:
        assert f.read().splitlines() == lines
    assert read_labels(path)[2] == [_episode(0), _episode(1)]


def test_a_cut_member_is_dropped_and_trimmed_before_the_next_append(tmp_path):
    path = tmp_path / "a.labels.jsonl.gz"
    for record in [HEADER, _episode(0)]:
        append_line(path, record)
    good = path.read_bytes()
    append_line(path, _episode(1))
    path.write_bytes(path.read_bytes()[:len(good) + 12])  # a kill mid-write of episode 1
    lines, whole = read_lines(path)
    assert whole == len(good) and len(lines) == 2
    assert [r["episode"] for r in read_labels(path)[2]] == [0]
    cut_after(path, whole)
    append_line(path, _episode(2))
    assert [r["episode"] for r in read_labels(path)[2]] == [0, 2]


def test_a_plain_file_is_gzipped_with_the_same_text_and_both_are_refused(tmp_path):
    plain = tmp_path / "r.labels.jsonl"
    text = "".join(json.dumps(r) + "\n" for r in [HEADER, _episode(0), _episode(1)])
    plain.write_text(text + '{"episode": 2, "obj')  # its last line cut by a kill
    assert [r["episode"] for r in read_labels(plain)[2]] == [0, 1]
    gz = tmp_path / "r.labels.jsonl.gz"
    gzip_plain_labels(gz)
    assert not plain.exists() and read_text(gz) == (text, None)  # the same text: cache keys hold
    plain.write_text(text)
    with pytest.raises(InputError, match="both hold labels"):
        gzip_plain_labels(gz)
    assert plain.read_text() == text and read_text(gz)[0] == text  # neither touched


def test_rewriting_the_same_lines_gives_the_same_bytes(tmp_path):
    """mtime 0 in every member: a merge rewritten from the same parts leaves git a clean diff."""
    lines = [json.dumps(HEADER), json.dumps(_episode(3))]
    write_lines(tmp_path / "a.gz", lines)
    write_lines(tmp_path / "b.gz", lines)
    assert (tmp_path / "a.gz").read_bytes() == (tmp_path / "b.gz").read_bytes()
