"""A mesh library remembers what it was built from (issue 63, provenance): a rerun of `objects
--source` after a mesh file changed builds that object again, saying so, instead of keeping the
old shape; an unchanged file is kept as built."""

from __future__ import annotations

import json

import trimesh

from corn_drake.cli import main


def _write_box(path, extents):
    path.write_text(trimesh.exchange.obj.export_obj(trimesh.creation.box(extents=extents)))


def test_a_changed_mesh_is_built_again_and_an_unchanged_one_kept(tmp_path, capsys):
    source, out = tmp_path / "meshes", tmp_path / "lib"
    source.mkdir()
    _write_box(source / "crate.obj", [0.08, 0.06, 0.04])
    _write_box(source / "brick.obj", [0.09, 0.05, 0.03])
    argv = ["objects", "--source", str(source), "--out", str(out), "--drops", "8",
            "--unit", "m", "--keep-size", "--no-progress"]
    assert main(argv) == 0
    built = {o["source"]: o for o in json.loads((out / "manifest.json").read_text())["objects"]}
    capsys.readouterr()
    _write_box(source / "crate.obj", [0.16, 0.06, 0.04])  # the user fixed its length
    assert main(argv) == 0
    said = capsys.readouterr().out
    assert "crate.obj: changed since library" in said and "brick.obj" not in said
    again = {o["source"]: o for o in json.loads((out / "manifest.json").read_text())["objects"]}
    assert again["crate.obj"]["id"] == built["crate.obj"]["id"]
    assert again["crate.obj"]["radius"] > built["crate.obj"]["radius"] * 1.3
    assert again["brick.obj"] == built["brick.obj"]
