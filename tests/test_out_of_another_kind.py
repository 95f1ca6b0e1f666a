"""`--out` naming a run folder of another kind (issue 63: a primitive run given to `train
--policy corn` said "invalid config ... unknown fields"): one line naming what the folder holds
and the command that resumes it, and nothing in the folder changed."""

import shutil

import pytest

from corn_drake.cli import main
from tests.paths import REPO_ROOT

SHIPPED = REPO_ROOT / "models" / "weights"
COMMANDS = {"primitive": ["train", "--policy", "primitive", "--encoder",
                          str(SHIPPED / "push_corn" / "encoder.pt")],
            "train": ["train", "--policy", "corn"],
            "distill": ["distill", "--run", str(SHIPPED / "push_corn")]}
# A shipped folder of each kind: (its kind, what the refusal calls it, its resuming command).
HELD = {"push_primitive": ("primitive", "a contact-primitive run", "train --policy primitive"),
        "push_corn": ("train", "a dense PPO teacher run", "train --policy POLICY"),
        "push_student": ("distill", "a DAgger student run", "distill")}
PAIRS = [(f, c) for f in sorted(HELD) for c in sorted(COMMANDS) if HELD[f][0] != c]


@pytest.mark.parametrize("folder, command", PAIRS)
def test_an_out_of_another_kind_is_named_with_its_own_command(tmp_path, capsys, folder,
                                                              command):
    out = tmp_path / folder
    out.mkdir()
    shutil.copy(SHIPPED / folder / "config.yaml", out / "config.yaml")
    before = (out / "config.yaml").read_bytes()
    _, words, resumer = HELD[folder]
    code = main([*COMMANDS[command], "--steps", "10", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert f"holds {words}" in err[0] and f"corn-drake {resumer} --out {out}" in err[0]
    assert sorted(p.name for p in out.iterdir()) == ["config.yaml"]
    assert (out / "config.yaml").read_bytes() == before


@pytest.mark.parametrize("source, words", [("push_primitive", "a contact-primitive run"),
                                           ("push_student", "a DAgger student run")])
def test_init_from_a_run_of_another_kind_names_what_it_is(tmp_path, capsys, source, words):
    out = tmp_path / "new"
    code = main(["train", "--policy", "corn", "--init-from", str(SHIPPED / source),
                 "--steps", "10", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and f"{words}; a dense teacher starts only" in err[0]
    assert not out.exists()

