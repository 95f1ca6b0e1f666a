"""Own meshes as a feature (issue 55): `objects --source MESHDIR` says each mesh's size rule on
screen (its size in the file, the unit read, the scale applied), `--keep-size` keeps real sizes
that fit and refuses, saying why, those that do not, and a library without the split asked for
names the split that has objects. Small boxes written by the test: convex, so no CoACD runs."""

from __future__ import annotations

import json

import pytest
import trimesh

from corn_drake.assets.ingest import detect_unit
from corn_drake.cli import main


@pytest.mark.parametrize("size, suffix, unit", [
    (0.08, ".obj", "metres"), (80.0, ".stl", "millimetres"), (8.0, ".obj", "centimetres"),
    (600.0, ".off", "millimetres"), (8.0, ".glb", "metres"), (1e6, ".obj", "metres")])
def test_the_unit_is_read_from_the_size(size, suffix, unit):
    assert detect_unit(size, suffix)[0] == unit


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    src = tmp_path_factory.mktemp("meshes")
    trimesh.creation.box([6.0, 4.0, 8.0]).export(src / "box_cm.obj")  # a 6 x 4 x 8 cm box in cm
    trimesh.creation.box([60.0, 40.0, 80.0]).export(src / "box_mm.stl")  # the same in mm
    trimesh.creation.box([0.01, 0.01, 0.01]).export(src / "tiny.obj")  # 1 cm: below the pads
    return src


def _ingest(tmp_path, src, capsys, *extra):
    out = tmp_path / "lib"
    code = main(["objects", "--source", str(src), "--drops", "8", "--out", str(out),
                 "--no-progress", *extra])
    return code, out, capsys.readouterr().out


def test_each_mesh_is_rescaled_saying_its_unit_and_scale(tmp_path, meshes, capsys):
    code, out, text = _ingest(tmp_path, meshes, capsys)
    assert code == 0, text
    assert "box_cm.obj): 6 x 4 x 8 in the file, read as centimetres" in text
    assert "box_mm.stl): 60 x 40 x 80 in the file, read as millimetres" in text
    assert "rescaled x" in text and "--keep-size keeps real sizes" in text
    objects = json.loads((out / "manifest.json").read_text())["objects"]
    box = next(o for o in objects if o["source"] == "box_mm.stl")
    assert box["scale"]["unit"] == "millimetres" and not box["scale"]["kept_size"]
    assert 0.05 <= box["radius"] <= 0.10
    assert any("read as millimetres" in w for w in box["warnings"])


def test_keep_size_keeps_what_fits_and_refuses_what_does_not(tmp_path, meshes, capsys):
    code, out, text = _ingest(tmp_path, meshes, capsys, "--keep-size")
    assert code == 0, text
    manifest = json.loads((out / "manifest.json").read_text())
    radii = {o["source"]: o["radius"] for o in manifest["objects"]}
    real = (0.03 ** 2 + 0.02 ** 2 + 0.04 ** 2) ** 0.5  # the box's half diagonal, 5.4 cm
    assert radii["box_cm.obj"] == pytest.approx(real, rel=1e-6)
    assert radii["box_mm.stl"] == pytest.approx(real, rel=1e-6)
    assert "kept at its real size (--keep-size)" in text
    reason = next(r["reason"] for r in manifest["rejected"] if r["source"] == "tiny.obj")
    assert "--keep-size" in reason and "smaller than" in reason and "0.866 cm" in reason
    assert f"rejected tiny.obj: {reason}" in text
    assert "every object is train" in text and "--split all" in text  # two boxes: one split
    # The library was made with --keep-size: resuming it without is refused, naming it.
    assert main(["objects", "--source", str(meshes), "--drops", "8", "--out", str(out),
                 "--no-progress"]) == 2
    assert "--keep-size" in capsys.readouterr().err


def test_a_given_unit_overrides_the_size_guess(tmp_path, capsys):
    """A 12 cm box written in centimetres ("12") reads as 1.2 cm in millimetres, and
    --keep-size then refuses it as smaller than the pads; --unit cm keeps it at 12 cm."""
    assert detect_unit(12.0, ".obj")[0] == "millimetres"
    assert detect_unit(12.0, ".obj", "cm")[:2] == ("centimetres", 0.01)
    assert detect_unit(8.0, ".glb", "mm")[0] == "millimetres"  # said beats the format's own
    src = tmp_path / "meshes"
    src.mkdir()
    trimesh.creation.box([12.0, 8.0, 6.0]).export(src / "box_12cm.obj")
    code, out, text = _ingest(tmp_path, src, capsys, "--keep-size", "--unit", "cm")
    assert code == 0 and "read as centimetres (given by --unit)" in text
    entry = json.loads((out / "manifest.json").read_text())["objects"][0]
    assert entry["scale"]["unit"] == "centimetres" and entry["scale"]["kept_size"]
    assert abs(entry["radius"] - 0.5 * (0.12 ** 2 + 0.08 ** 2 + 0.06 ** 2) ** 0.5) < 1e-3
    # The same folder without --unit reads millimetres: too small to keep, rejected saying so;
    # a folder none of whose meshes became an object is a failed command, not an empty success.
    (tmp_path / "guess").mkdir()
    code, _, text = _ingest(tmp_path / "guess", src, capsys, "--keep-size")
    assert code == 2 and "read as millimetres, from its size" in text
    assert main(["objects", "--unit", "cm", "--out", str(tmp_path / "p")]) == 2
    assert "--unit cm" in capsys.readouterr().err


def test_keep_size_is_for_mesh_folders_only(tmp_path, capsys):
    assert main(["objects", "--keep-size", "--out", str(tmp_path / "lib")]) == 2
    assert "--keep-size" in capsys.readouterr().err
    assert not (tmp_path / "lib").exists()


def test_a_library_without_the_split_asked_for_names_the_one_it_has(tmp_path, meshes, capsys):
    code, out, _ = _ingest(tmp_path, meshes, capsys, "--keep-size")
    assert code == 0
    assert main(["evaluate", "--run", "scripted", "--objects", str(out),
                 "--report", str(tmp_path / "r.json")]) == 2
    err = capsys.readouterr().err
    assert "no unseen objects" in err and "--split all" in err and "--split train" in err
