"""The library manifest's typed schema: what reads, what is refused (named), what round-trips."""

import json

import pytest

from corn_drake.assets.manifest import (LibraryObject, Manifest, Rejection, read_manifest,
                                        write_manifest)
from corn_drake.errors import InputError

ENTRY = {"id": "box_a", "split": "train", "family": "cuboid", "source": "fixture", "radius": 0.05,
         "mass": 0.2, "thin": False, "hulls": ["box_a/hull_00.obj"], "visual": "box_a/visual.obj",
         "cloud": "box_a/cloud.npy", "stable_poses": "box_a/stable_poses.npy",
         "drops": {"verified": 3, "held_second_setting": 3}, "timings": {"total_s": 1.5}}


def _write(folder, data):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "manifest.json").write_text(json.dumps(data))
    return folder


def test_entries_read_as_typed_records(tmp_path):
    # A library from before split_rule / unseen groups / the bookkeeping keys still reads.
    lib = _write(tmp_path / "lib", {"objects": [ENTRY, {**ENTRY, "id": "cyl_u", "split": "unseen",
                                                        "radius": 1}]})
    manifest = read_manifest(lib)
    box, cyl = manifest.objects
    assert isinstance(box, LibraryObject) and box.hulls == ["box_a/hull_00.obj"]
    assert box.unseen_group is None and box.warnings == [] and cyl.radius == 1
    assert manifest.rejected == [] and manifest.split_rule is None
    assert manifest.ids() == ["box_a", "cyl_u"] and manifest.ids("unseen") == ["cyl_u"]
    with pytest.raises(InputError, match="'nosuch' not in library"):
        manifest.get(lib, "nosuch")


@pytest.mark.parametrize("change, named", [
    ({"radius": "big"}, "'radius' must be float"),
    ({"hulls": "hull.obj"}, "'hulls' must be list"),
    ({"thin": "no"}, "'thin' must be bool"),
    ({"split": "test"}, "split 'test'"),
    ({"split": None}, "'split' must be str"),
    ({"id": ""}, "has no 'id' string"),
])
def test_a_field_of_the_wrong_type_is_named_with_its_object(tmp_path, change, named):
    lib = _write(tmp_path / "lib", {"objects": [{**ENTRY, **change}]})
    with pytest.raises(InputError, match=named) as error:
        read_manifest(lib)
    assert str(lib / "manifest.json") in str(error.value)


def test_duplicates_and_bad_rejections_are_named(tmp_path):
    with pytest.raises(InputError, match="'box_a' appears twice"):
        read_manifest(_write(tmp_path / "a", {"objects": [ENTRY, ENTRY]}))
    with pytest.raises(InputError, match=r"rejected\[0\] has no 'reason'"):
        read_manifest(_write(tmp_path / "b", {"objects": [], "rejected": [{"source": "x.obj"}]}))


def test_require_names_the_missing_fields(tmp_path):
    obj = LibraryObject(id="box_a", split="train", radius=0.05)
    obj.require(tmp_path, ("radius",))
    with pytest.raises(InputError, match="'box_a' has no 'cloud', 'mass'"):
        obj.require(tmp_path, ("radius", "cloud", "mass"))


def test_writer_and_reader_round_trip_keeping_unknown_fields(tmp_path):
    manifest = Manifest(objects=[LibraryObject(id="box_a", split="unseen", family="cuboid",
                                               unseen_group="member", radius=0.05,
                                               extra={"made_by": "a later version"})],
                        rejected=[Rejection("broken.obj", "not watertight")],
                        split_rule={"seed": 3},
                        extra={"note": "kept", "timings": {"build_s": 2.0}})  # an older library's
    write_manifest(tmp_path, manifest)
    on_disk = json.loads((tmp_path / "manifest.json").read_text())
    assert on_disk["objects"][0]["made_by"] == "a later version" and on_disk["note"] == "kept"
    assert "extra" not in on_disk and "extra" not in on_disk["objects"][0]
    assert read_manifest(tmp_path) == manifest
