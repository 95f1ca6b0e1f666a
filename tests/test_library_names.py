"""Hostile names and files around an object library (issue 53), each refused in one line naming
the input, with nothing written and nothing of the user's lost:

- mesh files whose object ids meet (`cup a.obj` / `cup_a.obj`, `Cup.obj` / `cup.obj`,
  `cup.obj` / `cup.stl`, `sub/cup.obj` / `sub_cup.obj`, or a new file and an object the
  library already holds): the build is refused naming both files, before OUT is made;
- manifest paths that leave the library (`..`, absolute, a symbolic link pointing out) and ids
  that are no plain name;
- hull and visual meshes Drake cannot make a convex hull of (random bytes, empty, 2 vertices,
  flat, a NaN vertex): named before Drake sees them;
- a full disk while a checkpoint is written: the old checkpoints stay, one line says so.
"""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import pytest
import trimesh

from corn_drake.cli import main
from corn_drake.errors import DiskFullError, InputError
from tests.fixtures import one_error_line, write_loadable_library


@pytest.fixture(autouse=True)
def _one_line_errors(monkeypatch):
    """The CLI prints one line, not the traceback CORN_DRAKE_DEBUG=1 asks for."""
    monkeypatch.delenv("CORN_DRAKE_DEBUG", raising=False)


def _box(path: Path, size: float = 0.05) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box([size, 0.8 * size, 0.6 * size]).export(path)


# --- 1. object ids from file names cannot collide ------------------------------------------
@pytest.mark.parametrize("names", [("cup a.obj", "cup_a.obj"),   # separators made "_"
                                   ("Cup.obj", "cup.obj"),       # one folder on macOS/Windows
                                   ("cup.obj", "cup.stl"),       # the same stem
                                   ("sub/cup.obj", "sub_cup.obj")])  # a folder made "_"
def test_meshes_meeting_on_one_id_are_refused_before_anything_is_written(tmp_path, capsys, names):
    source, out = tmp_path / "meshes", tmp_path / "lib"
    for i, name in enumerate(names):
        _box(source / name, 0.05 + 0.01 * i)
    before = sorted(p.relative_to(source) for p in source.rglob("*"))
    assert main(["objects", "--source", str(source), "--out", str(out), "--drops", "8",
                 "--no-progress"]) == 2
    err = one_error_line(capsys, *(repr(n) for n in names), str(source), "rename")
    assert "mesh_" in err
    assert not out.exists()  # refused before the library folder (or its lock) was made
    assert sorted(p.relative_to(source) for p in source.rglob("*")) == before


def test_a_new_mesh_meeting_an_object_the_library_holds_is_refused(tmp_path):
    """A resumed build: the library holds mesh_cup_a from cup_a.obj (since moved away); a new
    `cup a.obj` must not overwrite its folder. The manifest stays byte for byte."""
    from corn_drake.assets.library import ingest_folder

    source, out = tmp_path / "meshes", tmp_path / "lib"
    _box(source / "cup a.obj")
    out.mkdir()
    entry = {"id": "mesh_cup_a", "split": "train", "family": "ingested", "source": "cup_a.obj"}
    (out / "manifest.json").write_text(json.dumps({"objects": [entry], "rejected": []}))
    before = (out / "manifest.json").read_bytes()
    with pytest.raises(InputError) as refused:
        ingest_folder(source, out, progress=False)
    message = str(refused.value)
    assert "'cup a.obj'" in message and "'cup_a.obj'" in message and "already holds" in message
    assert len(message.splitlines()) == 1
    assert (out / "manifest.json").read_bytes() == before
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json"]


def test_distinct_names_keep_their_ids(tmp_path):
    """Only meshes get ids (cup.txt is rejected later with its reason, so it meets no one); a
    file whose object was built before keeps its id on a resume."""
    from corn_drake.assets.library import ingested_ids
    from corn_drake.assets.manifest import LibraryObject, Manifest

    source = tmp_path / "meshes"
    for name in ("cup.obj", "mug.STL", "sub/cup.obj"):
        _box(source / name)
    (source / "cup.txt").write_text("notes")
    files = sorted(p for p in source.rglob("*") if p.is_file())
    resumed = Manifest(objects=[LibraryObject(id="mesh_cup", source="cup.obj")])
    assert ingested_ids(source, files, resumed, tmp_path / "lib") == {
        "cup.obj": "mesh_cup", "mug.STL": "mesh_mug", "sub/cup.obj": "mesh_sub_cup"}


# --- 2. every path in a manifest stays inside the library ------------------------------------
def _library(tmp_path: Path) -> Path:
    return write_loadable_library(tmp_path / "lib", 1, 0)


def _edit(library: Path, **fields) -> None:
    path = library / "manifest.json"
    data = json.loads(path.read_text())
    data["objects"][0].update(fields)
    path.write_text(json.dumps(data))


@pytest.mark.parametrize("field, value, problem", [
    ("hulls", ["../../../../etc/hostname"], "leads outside the library"),
    ("hulls", ["box_00/../../outside.obj"], "leads outside the library"),
    ("hulls", ["/etc/hostname"], "is absolute"),
    ("visual", "/etc/hostname", "is absolute"),
    ("cloud", "../cloud.npy", "leads outside the library"),
    ("stable_poses", "box_00/\0.npy", "NUL"),
])
def test_manifest_paths_leaving_the_library_are_refused(tmp_path, field, value, problem):
    from corn_drake.assets.library import list_objects, load_object_spec

    library = _library(tmp_path)
    _edit(library, **{field: value})
    for read in (lambda: list_objects(library), lambda: load_object_spec(library, "box_00")):
        with pytest.raises(InputError) as refused:
            read()
        message = str(refused.value)
        assert len(message.splitlines()) == 1, message
        for needle in (str(library / "manifest.json"), "'box_00'", field, problem):
            assert needle in message, (needle, message)


def test_a_symlink_pointing_out_of_the_library_is_refused(tmp_path, capsys):
    from corn_drake.assets.content_hash import library_content_hash
    from corn_drake.assets.library import load_object_spec

    library = _library(tmp_path)
    outside = tmp_path / "outside"
    outside.mkdir()
    hull = library / "box_00" / "hull_00.obj"
    (outside / "hull.obj").write_bytes(hull.read_bytes())  # a valid mesh: only where it lies counts
    library_content_hash(library)
    load_object_spec(library, "box_00")
    hull.unlink()
    hull.symlink_to(outside / "hull.obj")
    for read in (lambda: load_object_spec(library, "box_00"),
                 lambda: library_content_hash(library)):
        with pytest.raises(InputError, match=r"object 'box_00' hulls path 'box_00/hull_00.obj' "
                                             r"resolves \(through a symbolic link\) outside"):
            read()
    # A link that stays inside the library is a file of the library.
    hull.unlink()
    hull.symlink_to(library / "box_00" / "visual.obj")
    load_object_spec(library, "box_00")
    # The same through a command that reads the library (clouds): one line, exit 2.
    cloud = library / "box_00" / "cloud.npy"
    (outside / "cloud.npy").write_bytes(cloud.read_bytes())
    cloud.unlink()
    cloud.symlink_to(outside / "cloud.npy")
    assert main(["contact-data", "--objects", str(library), "--num-samples", "8",
                 "--out", str(tmp_path / "out")]) == 2
    one_error_line(capsys, str(library / "manifest.json"), "'box_00'", "box_00/cloud.npy")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("object_id", ["../evil", "a/b", "..", "a\\b"])
def test_ids_that_are_no_plain_name_are_refused(tmp_path, object_id):
    """Ids name output files (gallery ID.png, evaluation episode_K_ID.html)."""
    from corn_drake.assets.library import list_objects

    library = _library(tmp_path)
    _edit(library, id=object_id)
    with pytest.raises(InputError, match="must be a plain name") as refused:
        list_objects(library)
    assert repr(object_id) in str(refused.value)


# --- 3. a garbage hull is named before Drake sees it ---------------------------------------
@pytest.mark.parametrize("content, problem", [
    (bytes(range(256)) * 4, "not OBJ text"),
    (b"", "missing or empty"),
    (b"v 0 0 0\nv 1 0 0\nf 1 2 2\n", "has 2 vertices"),
    (b"# nothing but a comment\n", "has 0 vertices"),
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\n", "in one plane"),
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 nan\n", "not three finite numbers"),
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0\n", "not three finite numbers"),
])
@pytest.mark.parametrize("mesh", ["hull_00.obj", "visual.obj"])
def test_a_garbage_mesh_is_one_line_naming_it(tmp_path, content, problem, mesh):
    from corn_drake.assets.library import load_object_spec

    library = _library(tmp_path)
    (library / "box_00" / mesh).write_bytes(content)
    with pytest.raises(InputError) as refused:
        load_object_spec(library, "box_00")
    message = str(refused.value)
    assert len(message.splitlines()) == 1, message
    for needle in (str(library / "box_00" / mesh), "'box_00'", problem):
        assert needle in message, (needle, message)


def test_a_garbage_hull_ends_a_command_in_one_line(tmp_path, capsys):
    """Through the CLI, where Drake's MakeConvexHull traceback used to come out: `train` checks
    its library's objects before it writes anything."""
    library = _library(tmp_path)
    hull = library / "box_00" / "hull_00.obj"
    hull.write_bytes(b"v 0 0 0\nv 1 0 0\n")
    out = tmp_path / "run"
    assert main(["train", "--policy", "state", "--objects", str(library), "--steps", "64",
                 "--out", str(out)]) == 2
    one_error_line(capsys, str(hull), "has 2 vertices", "'box_00'")
    assert not out.exists()


# --- 4. a full disk while a checkpoint is written -------------------------------------------
class _FullDisk:
    """A file whose writes fail with ENOSPC once `room` bytes are written."""

    def __init__(self, file, room: int):
        self.file, self.room = file, room

    def write(self, data):
        if len(data) > self.room:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.room -= len(data)
        return self.file.write(data)

    def __getattr__(self, name):
        return getattr(self.file, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.file.close()


def _fill_disk(monkeypatch, room: int = 1000) -> None:
    """Every file checkpoint_files opens for writing fills up after `room` bytes, and the disk
    reports `room` bytes free."""
    import collections
    import shutil

    from corn_drake.storage import checkpoint_files

    usage = collections.namedtuple("usage", "total used free")
    real_usage = shutil.disk_usage
    monkeypatch.setattr("shutil.disk_usage", lambda p: usage(*real_usage(p)[:2], room))

    def full_open(path, mode="r", *args, **kwargs):
        f = open(path, mode, *args, **kwargs)
        return _FullDisk(f, room) if "w" in mode else f

    monkeypatch.setattr(checkpoint_files, "open", full_open, raising=False)


def _checkpoints(tmp_path: Path) -> Path:
    import torch

    from corn_drake.storage.checkpoint_files import save_checkpoint

    path = tmp_path / "run" / "checkpoints" / "last.pt"
    save_checkpoint(path, {"step": 1, "w": torch.zeros(1000)})
    save_checkpoint(path, {"step": 2, "w": torch.ones(1000)})
    return path


def test_a_full_disk_keeps_the_previous_checkpoint_and_says_so(tmp_path, monkeypatch):
    import torch

    from corn_drake.storage.checkpoint_files import load_checkpoint, save_checkpoint

    path = _checkpoints(tmp_path)
    before = {p.name: p.read_bytes() for p in path.parent.iterdir()}
    assert sorted(before) == ["last.pt", "prev.pt"]
    _fill_disk(monkeypatch)
    # torch's own writer would turn the failed write into a RuntimeError saying nothing of why.
    with pytest.raises(DiskFullError) as full:
        save_checkpoint(path, {"step": 3, "w": torch.full((1000,), 3.0)})
    message = str(full.value)
    assert len(message.splitlines()) == 1, message
    assert isinstance(full.value, OSError) and isinstance(full.value.__cause__, OSError)
    for needle in ("no space left", str(path), str(path.with_name("prev.pt")), "kept unchanged",
                   f"in {path.parent}", "free about", "run the same command again"):
        assert needle in message, (needle, message)
    assert {p.name: p.read_bytes() for p in path.parent.iterdir()} == before  # no temporaries
    assert load_checkpoint(path)["step"] == 2


def test_a_full_disk_while_rotating_keeps_both_checkpoints(tmp_path, monkeypatch):
    """The new checkpoint fits, the copy of the old one to prev.pt does not."""
    import torch

    from corn_drake.storage.checkpoint_files import load_checkpoint, save_checkpoint

    path = _checkpoints(tmp_path)
    before = {p.name: p.read_bytes() for p in path.parent.iterdir()}

    def full_copy(src, dst, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr("shutil.copyfile", full_copy)
    with pytest.raises(DiskFullError, match="kept unchanged"):
        save_checkpoint(path, {"step": 3, "w": torch.full((1000,), 3.0)})
    assert {p.name: p.read_bytes() for p in path.parent.iterdir()} == before
    assert load_checkpoint(path)["step"] == 2


def test_the_cli_prints_a_full_disk_in_one_line(tmp_path, monkeypatch, capsys):
    """A checkpoint's DiskFullError, and any other write failing for want of space (named by
    atomic_path), end a command in one line and exit 2, not a traceback."""
    import torch

    from corn_drake.commands.datasets import objects
    from corn_drake.storage.atomic_files import write_json
    from corn_drake.storage.checkpoint_files import save_checkpoint

    path = _checkpoints(tmp_path)
    monkeypatch.setattr(objects, "run", lambda args: save_checkpoint(path, {"w": torch.ones(1000)}))
    _fill_disk(monkeypatch)
    assert main(["objects", "--out", str(tmp_path / "unused")]) == 2
    one_error_line(capsys, "no space left", str(path), "kept unchanged")

    def full_write(self, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    report = tmp_path / "report.json"
    monkeypatch.setattr(objects, "run", lambda args: write_json(report, {"a": 1}))
    monkeypatch.setattr(Path, "write_text", full_write)
    assert main(["objects", "--out", str(tmp_path / "unused")]) == 2
    one_error_line(capsys, "no space left", f"writing {report}", "run the same command again")
    assert not report.exists() and list(tmp_path.glob(".report.json.*")) == []
    # A copy that fills the disk (shutil names the source first, the target second): the
    # target is the file whose disk is full, so it is the one named.
    import shutil

    source, target = tmp_path / "mesh.obj", tmp_path / "copied.obj"
    source.write_bytes(b"v 0 0 0\n" * 1000)

    def full_sendfile(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "sendfile", full_sendfile)
    monkeypatch.setattr(objects, "run", lambda args: shutil.copyfile(source, target))
    assert main(["objects", "--out", str(tmp_path / "unused")]) == 2
    line = one_error_line(capsys, "no space left", f"writing {target}")
    assert str(source) not in line
