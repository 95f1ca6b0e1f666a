"""`corn-drake objects --workers N` builds the library a serial build does: the same files byte
for byte, the same manifest (objects in the same order) but for the build timings."""

import hashlib
import json
from pathlib import Path

import pytest

from corn_drake.cli import main


def _files(library: Path) -> dict[str, str]:
    """sha256 of every file of the library except the manifest, the lock and the argument
    record (which name this build, not its objects) and the decomposition cache."""
    skip = {"manifest.json", ".lock", "arguments.json"}
    return {str(p.relative_to(library)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(library.rglob("*"))
            if p.is_file() and p.name not in skip and ".coacd_cache" not in p.parts}


def _manifest(library: Path) -> dict:
    data = json.loads((library / "manifest.json").read_text())
    data.pop("timings", None)
    for obj in data["objects"]:  # how long each step took, and nothing else, may differ
        obj.pop("timings", None)
        obj.get("drops", {}).pop("second_setting_s", None)
    return data


@pytest.mark.slow
def test_two_workers_build_the_serial_library(tmp_path):
    # --num 14 --split unseen: the two held-out-family objects (bottle_000, wedge_000).
    common = ["objects", "--num", "14", "--seed", "0", "--split", "unseen", "--drops", "16",
              "--no-progress"]
    assert main([*common, "--out", str(tmp_path / "serial")]) == 0
    assert main([*common, "--workers", "2", "--out", str(tmp_path / "pool")]) == 0
    serial, pool = tmp_path / "serial", tmp_path / "pool"
    assert _files(serial) and _files(serial) == _files(pool)
    assert _manifest(serial) == _manifest(pool)
    assert [o["id"] for o in _manifest(pool)["objects"]] == ["bottle_000", "wedge_000"]


def test_workers_must_be_a_positive_count(capsys):
    with pytest.raises(SystemExit) as e:
        main(["objects", "--workers", "0", "--out", "x"])
    assert e.value.code == 2
    assert "--workers" in capsys.readouterr().err
