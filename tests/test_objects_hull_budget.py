"""`objects --max-hulls`: the hull budget reaches CoACD, is recorded with the library (a resume
with another is refused), and a card's library command always names it."""

import json

import pytest

from corn_drake.assets.processing.decompose import DecompositionConfig, decompose
from corn_drake.cli import main
from corn_drake.commands.datasets import objects
from corn_drake.commands.reporting.ship import library_arguments, with_hull_budget
from corn_drake.errors import InputError
from tests.fixtures import one_error_line

MUG_SEED = 137592312  # a mug CoACD cuts into more than 4 hulls with the default budget


def test_the_default_budget_is_the_decompositions_own():
    assert objects.DEFAULT_MAX_HULLS == DecompositionConfig().max_convex_hull


def test_coacd_keeps_a_mug_within_the_budget():
    from corn_drake.assets.families import make_family_mesh
    from corn_drake.assets.processing.process import normalise

    mesh = normalise(make_family_mesh("mug", MUG_SEED), 0.08)
    free, _, _ = decompose(mesh, DecompositionConfig(), None)
    capped, _, _ = decompose(mesh, DecompositionConfig(max_convex_hull=4), None)
    assert len(free) > 4 >= len(capped) >= 1
    # Fewer hulls cover the same mug more coarsely, never less of it.
    assert sum(h.volume for h in capped) >= 0.95 * mesh.volume


def test_the_flag_reaches_the_build_and_a_resume_with_another_is_refused(tmp_path, monkeypatch,
                                                                          capsys):
    from corn_drake.assets import library
    from corn_drake.assets.manifest import Manifest

    seen = []
    monkeypatch.setattr(library, "build_procedural",
                        lambda out, num, seed, cfg, *a, **k: seen.append(
                            cfg.decomposition.max_convex_hull) or Manifest())
    out = tmp_path / "lib"
    assert main(["objects", "--num-objects", "2", "--max-hulls", "8", "--out", str(out)]) == 0
    assert seen == [8]
    assert json.loads((out / "arguments.json").read_text())["--max-hulls"] == 8
    assert main(["objects", "--num-objects", "2", "--out", str(out)]) == 2
    one_error_line(capsys, "--max-hulls: recorded 8, requested 16")
    for bad in ("0", "-3", "two"):
        with pytest.raises(SystemExit):
            main(["objects", "--num-objects", "2", "--max-hulls", bad, "--out", str(tmp_path / "x")])
        assert "--max-hulls" in capsys.readouterr().err


def test_a_cards_library_command_names_the_budget_its_library_was_built_with(tmp_path):
    lib = tmp_path / "lib"
    lib.mkdir()
    command = f"corn-drake objects --num-objects 80 --seed 0 --split unseen --out {lib}"
    # A library recorded before the flag existed was built with 16.
    assert with_hull_budget(command, library_arguments(command)) == f"{command} --max-hulls 16"
    (lib / "arguments.json").write_text(json.dumps({"--seed": 0, "--max-hulls": 8}))
    assert with_hull_budget(command, library_arguments(command)) == f"{command} --max-hulls 8"
    named = f"{command} --max-hulls 8"
    assert with_hull_budget(named, library_arguments(named)) == named
    with pytest.raises(InputError, match="names --max-hulls 16, but .* was built with 8"):
        wrong = f"{command} --max-hulls 16"
        with_hull_budget(wrong, library_arguments(wrong))
