"""A card says only what is true (issue 63, provenance): `ship` recomputes what it quotes from
the report's own episodes (an edited success rate, balanced rate or `complete` is refused),
packs only the very weights the report measured (config, checkpoint and chooser files hashed:
retrained to the same step count, or a config edited, is refused), and names a library the
report played on (no shared object: refused). The card carries the at-rest figure beside the
paper's rule. One real evaluation of a teacher run (the shipped push_corn copied) and one
ship per probe."""

from __future__ import annotations

import json
import shutil

import pytest

from corn_drake.cli import main
from tests.paths import REPO_ROOT


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory):
    from tests.fixtures import write_loadable_library

    root = tmp_path_factory.mktemp("provenance")
    run = root / "run"
    shutil.copytree(REPO_ROOT / "models" / "weights" / "push_corn", run)
    (run / "card.json").unlink()
    library = write_loadable_library(root / "lib", 1, num_unseen=2)
    report = root / "eval.json"
    assert main(["evaluate", "--run", str(run), "--objects", str(library), "--split", "unseen",
                 "--episodes", "2", "--record", "0", "--no-progress", "--report",
                 str(report)]) == 0
    return run, library, report


def _ship(run, library, report, out):
    return main(["ship", "--run", str(run), "--report", str(report), "--library-command",
                 f"corn-drake objects --num-objects 3 --seed 0 --split unseen --out {library}",
                 "--out", str(out)])


def _edited(report, tmp_path, **changes):
    data = json.loads(report.read_text())
    data.update(changes)
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(data))
    return path


def test_the_report_as_written_ships_with_both_success_figures(evaluated, tmp_path):
    run, library, report = evaluated
    data = json.loads(report.read_text())
    assert len(data["weights_sha256"]) == 64
    assert _ship(run, library, report, tmp_path / "w") == 0
    card = json.loads((tmp_path / "w" / "card.json").read_text())
    assert card["success_rate"] == data["success_rate"]
    assert card["successes_ending_at_rest"] <= round(card["success_rate"] * card["episodes"])
    assert card["success_rate_ending_at_rest"] == card["successes_ending_at_rest"] / 2


@pytest.mark.parametrize("changes, said", [
    ({"success_rate": 0.9}, "is not its 2 episodes'"),
    ({"balanced_success_rate": 0.7}, "balanced_success_rate 0.7 is not"),
    ({"complete": False}, "says complete: False with 2 of the 2"),
])
def test_an_edited_number_is_refused(evaluated, tmp_path, capsys, changes, said):
    run, library, report = evaluated
    assert _ship(run, library, _edited(report, tmp_path, **changes), tmp_path / "w") == 2
    assert said in capsys.readouterr().err
    assert not (tmp_path / "w").exists()


def test_a_report_saying_complete_for_part_of_its_episodes_is_refused(evaluated, tmp_path,
                                                                      capsys):
    run, library, report = evaluated
    data = json.loads(report.read_text())
    one = data["episodes"][:1]
    edited = _edited(report, tmp_path, episodes=one, episodes_requested=8, complete=True,
                     success_rate=float(one[0]["success"]),
                     balanced_success_rate=float(one[0]["success"]))
    assert _ship(run, library, edited, tmp_path / "w") == 2
    assert "complete: True with 1 of the 8" in capsys.readouterr().err


def test_other_weights_or_an_edited_config_are_refused(evaluated, tmp_path, capsys):
    """The same step count, other weights (a retrain): the hash tells them apart."""
    import torch

    from corn_drake.storage.checkpoint_files import load_checkpoint, save_checkpoint

    run, library, report = evaluated
    other = tmp_path / "run"
    shutil.copytree(run, other)
    checkpoint = other / "checkpoints" / "last.pt"
    state = load_checkpoint(checkpoint)
    for name, tensor in state["agent"].items():
        if torch.is_floating_point(tensor):
            state["agent"][name] = tensor + 0.01
            break
    save_checkpoint(checkpoint, state, keep_previous=False)
    retrained = _edited(report, tmp_path, run=str(other))
    assert _ship(other, library, retrained, tmp_path / "w") == 2
    assert "measured other weights" in capsys.readouterr().err
    edited = tmp_path / "run2"
    shutil.copytree(run, edited)
    config = edited / "config.yaml"
    config.write_text(config.read_text() + "\n# edited\n")
    assert _ship(edited, library, _edited(report, tmp_path, run=str(edited)),
                 tmp_path / "w") == 2
    assert "weights_sha256 differs" in capsys.readouterr().err


def test_a_library_the_report_never_played_on_is_refused(evaluated, tmp_path, capsys):
    from tests.fixtures import write_loadable_library

    run, _, report = evaluated
    other = tmp_path / "other_lib"
    write_loadable_library(other, 1, num_unseen=1)
    text = (other / "manifest.json").read_text()
    for obj in json.loads(text)["objects"]:  # the same shapes renamed: no shared object
        (other / obj["id"]).rename(other / f"x{obj['id']}")
        text = text.replace(f'"{obj["id"]}', f'"x{obj["id"]}')
    (other / "manifest.json").write_text(text)
    assert _ship(run, other, report, tmp_path / "w") == 2
    assert "does not hold" in capsys.readouterr().err
