"""A card field of the wrong type is named, not diagnosed wrongly (issue 63, errors that name the
right thing): every field `ship` writes is checked against its type when a card is read
(storage/weights_card.py), by `evaluate --run <shipped folder>` and by `ship --out` on a shipped
folder; every card shipped today reads."""

from __future__ import annotations

import json
import shutil

import pytest

from corn_drake.cli import main
from corn_drake.errors import InputError
from corn_drake.storage.weights_card import FIELD_TYPES, read_card
from tests.fixtures import one_error_line
from tests.paths import REPO_ROOT

SHIPPED = sorted(p.parent for p in (REPO_ROOT / "models" / "weights").glob("*/card.json"))


@pytest.mark.parametrize("folder", SHIPPED, ids=lambda p: p.name)
def test_every_shipped_card_reads_and_every_field_it_holds_is_known(folder):
    card = read_card(folder)
    assert card and set(card) <= set(FIELD_TYPES), set(card) - set(FIELD_TYPES)


@pytest.mark.parametrize("field, value, said", [
    ("library_object_hashes", "a1b2", "should be an object"),  # read as "no shared object"
    ("library_object_hashes", {"box_00": 7}, "maps 'box_00' to an integer"),
    ("episodes", True, "should be an integer"),  # JSON true is no count
    ("success_rate", "0.84", "should be an integer or a number"),
    ("source_run", ["runs/a"], "should be a string"),
])
def test_a_field_of_the_wrong_type_is_named_in_one_line(tmp_path, field, value, said):
    folder = tmp_path / "shipped"
    folder.mkdir()
    card = json.loads((SHIPPED[0] / "card.json").read_text())
    card[field] = value
    (folder / "card.json").write_text(json.dumps(card))
    with pytest.raises(InputError, match=f"card.json: field '{field}' {said}"):
        read_card(folder)


def test_evaluate_and_ship_name_the_damaged_field(tmp_path, capsys):
    shipped = tmp_path / "push_state"
    shutil.copytree(REPO_ROOT / "models" / "weights" / "push_state", shipped)
    card = json.loads((shipped / "card.json").read_text())
    card["library_object_hashes"] = sorted(card["library_object_hashes"])  # a list of ids
    (shipped / "card.json").write_text(json.dumps(card))
    assert main(["evaluate", "--run", str(shipped), "--episodes", "1", "--record", "0",
                 "--report", str(tmp_path / "r.json"), "--no-progress"]) == 2
    one_error_line(capsys, "library_object_hashes", "should be an object, got a list")
    assert not (tmp_path / "r.json").exists()
    assert main(["ship", "--run", "runs/any", "--report", str(tmp_path / "r.json"),
                 "--library-command", "corn-drake objects --out data/x",
                 "--out", str(shipped)]) == 2
    one_error_line(capsys, f"--out {shipped}", "card cannot be read", "--overwrite")
