"""A library's content hash (assets/content_hash.py) and what a shipped card does with it
(evaluation/shipped_card.py): `evaluate` names the card's library command when the library is
missing, and warns when the library's objects are not the card's."""

import io
import json

import numpy as np
import pytest

from corn_drake.assets.content_hash import library_content_hash, object_hashes
from corn_drake.assets.manifest import read_manifest, write_manifest
from corn_drake.errors import InputError, MissingInputError
from corn_drake.evaluation.shipped_card import library_card_fields, require_library, warn_if_other_library
from tests.fixtures import write_loadable_library

COMMAND = "corn-drake objects --num-objects 80 --seed 0 --split unseen --out data/library_unseen"


@pytest.fixture
def library(tmp_path):
    return write_loadable_library(tmp_path / "lib", 2, num_unseen=1)


def test_the_hash_follows_the_objects_not_the_build_records(library):
    before = library_content_hash(library)
    manifest = read_manifest(library)
    manifest.objects[0].timings = {"total_s": 123.0}  # another run of the same build
    manifest.objects[0].drops = {"settled": 7}
    write_manifest(library, manifest)
    assert library_content_hash(library) == before
    poses = library / manifest.objects[0].stable_poses
    np.save(poses, np.load(poses) + np.array([0, 0, 1e-9, 0, 0, 0, 0]))  # another start height
    assert library_content_hash(library) != before


def test_a_subset_hashes_its_objects_as_the_whole_library_does(library):
    every = object_hashes(library)
    first = sorted(every)[0]
    assert object_hashes(library, [first]) == {first: every[first]}
    assert library_content_hash(library, list(every)) == library_content_hash(library)
    with pytest.raises(InputError, match="no object 'nothing'"):
        object_hashes(library, ["nothing"])


def _shipped(tmp_path, library) -> str:
    folder = tmp_path / "weights"
    folder.mkdir()
    (folder / "card.json").write_text(json.dumps({"library_command": COMMAND,
                                                  **library_card_fields(library)}))
    return str(folder)


def test_a_missing_library_from_the_card_names_its_command(tmp_path, library):
    run = _shipped(tmp_path, library)
    with pytest.raises(MissingInputError) as e:
        require_library(run, tmp_path / "data" / "library_unseen", given=False)
    assert "card.json" in str(e.value) and COMMAND in str(e.value)
    require_library(run, tmp_path / "elsewhere", given=True)  # --objects: its own error follows
    require_library(str(tmp_path), tmp_path / "nowhere", given=False)  # not a shipped folder


def test_evaluate_warns_once_when_the_library_is_not_the_cards(tmp_path, library):
    run = _shipped(tmp_path, library)
    ids = sorted(object_hashes(library))
    out = io.StringIO()
    warn_if_other_library(run, library, ids, stream=out)
    assert out.getvalue() == ""
    poses = library / read_manifest(library).get(library, ids[0]).stable_poses
    np.save(poses, np.load(poses) + np.array([0, 0, 1e-6, 0, 0, 0, 0]))  # 1 um higher starts
    warn_if_other_library(run, library, ids, stream=out)
    lines = out.getvalue().splitlines()
    assert len(lines) == 1 and lines[0].startswith("warning:") and ids[0] in lines[0], lines
    assert COMMAND in lines[0]
    # Objects the card's library does not hold are not compared: none shared is a warning too.
    out = io.StringIO()
    warn_if_other_library(run, library, ["mesh_other"], stream=out)
    assert "none of the evaluated objects" in out.getvalue()
