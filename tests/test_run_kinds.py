"""One registry of run kinds (rl/runs/kinds.py, issue 62): every kind declares how it is
recognised, loaded and configured, which of evaluate's per-kind flags it takes, what it adds to
a report, which runner plays it, what gallery paints and how ship packs it; the commands read
the declarations instead of testing the kind's name, and a new kind is one entry."""

from __future__ import annotations

import re

import pytest

from corn_drake.cli import main
from corn_drake.commands.evaluate import KIND_FLAGS
from corn_drake.rl.runs import kinds as run_kinds
from corn_drake.rl.runs.kinds import RUN_KINDS, load_any_run, run_kind_of
from tests.fixtures import one_error_line
from tests.paths import REPO_ROOT

WEIGHTS = REPO_ROOT / "models" / "weights"
# A run of every kind: a shipped folder where the kind has weights, else its name.
EXAMPLE = {"train": str(WEIGHTS / "push_state"), "distill": str(WEIGHTS / "push_student"),
           "primitive": str(WEIGHTS / "push_primitive"), "reference": "scripted",
           "planner": "planner"}
# What a flag's value looks like on the command line.
VALUES = {"perception": ["--perception", "geometric"], "attention": ["--attention"],
          "stochastic": ["--stochastic"], "workers": ["--workers", "2"],
          "ray_address": ["--ray-address", "127.0.0.1:1"]}


def test_every_kind_is_declared_and_has_an_example():
    assert set(RUN_KINDS) == set(EXAMPLE)
    for name, kind in RUN_KINDS.items():
        assert kind.NAME == name and kind.WHAT and kind.RUNNER in ("diagram", "planner")
        assert kind.FLAGS <= set(KIND_FLAGS)
        assert run_kind_of(EXAMPLE[name]) is kind  # recognised: by its folder or its name


@pytest.mark.parametrize("name", ["train", "distill", "primitive"])
def test_every_shipped_folder_loads_as_its_kind_with_its_weights(name):
    loaded = load_any_run(EXAMPLE[name])
    assert type(loaded) is RUN_KINDS[name] and loaded.kind == name
    fields = loaded.report_fields()
    assert fields["env_steps"] > 0 and re.fullmatch("[0-9a-f]{64}", fields["weights_sha256"])


def test_the_card_evaluate_checks_the_library_against_is_the_runs_or_the_experts_policys():
    # A shipped folder's own card; the expert's is its policy source's run (the candidates it
    # searches were learned and measured on that card's library); none without that source.
    assert load_any_run(EXAMPLE["primitive"]).card_run() == EXAMPLE["primitive"]
    expert = load_any_run("planner")
    expert.configure(None, [f"planner.policy={EXAMPLE['primitive']}"])
    assert expert.card_run() == EXAMPLE["primitive"]
    expert.configure(None, ["planner.sources=[push,turn]"])
    assert expert.card_run() is None


@pytest.mark.parametrize("name, flag", [(n, f) for n in EXAMPLE for f in KIND_FLAGS
                                        if f not in RUN_KINDS[n].FLAGS])
def test_a_flag_the_kind_does_not_take_is_refused_naming_both(tmp_path, capsys, name, flag):
    report = tmp_path / "r.json"
    argv = ["evaluate", "--run", EXAMPLE[name], *VALUES[flag], "--record", "0",
            "--report", str(report)]
    assert main(argv) == 2
    takers = [k.WHAT for k in RUN_KINDS.values() if flag in k.FLAGS]
    one_error_line(capsys, KIND_FLAGS[flag], takers[0], f"is {RUN_KINDS[name].WHAT}")
    assert not report.exists()


def test_a_new_kind_is_one_entry_listed_by_the_help(monkeypatch, capsys):
    class ReplayRun(run_kinds.ReferenceRun):
        NAME = "replay"
        WHAT = "a recorded action sequence"
        NAMES = ("replay",)
        FLAGS = frozenset({"stochastic"})

    monkeypatch.setitem(RUN_KINDS, "replay", ReplayRun)
    assert run_kind_of("replay") is ReplayRun
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "`replay`: a recorded action sequence" in help_text
    for kind in RUN_KINDS.values():
        assert kind.WHAT in help_text
    # The flags it declares are its own: --stochastic now applies to it as well.
    assert main(["evaluate", "--run", "scripted", "--stochastic", "--report", "r.json"]) == 2
    assert "a recorded action sequence" in capsys.readouterr().err


# The commands that load a run go through the registry, never a kind's loader or its name.
THROUGH_THE_REGISTRY = ["commands/evaluate.py", "commands/reporting/gallery.py", "commands/reporting/ship.py",
                        "evaluation/shipping.py", "commands/learning/distill.py", "commands/demo.py",
                        "commands/datasets/collect_outcomes.py", "commands/learning/fit_outcome.py",
                        "commands/datasets/label.py", "bench/episodes/planner.py"]


@pytest.mark.parametrize("module", THROUGH_THE_REGISTRY)
def test_the_commands_read_the_declarations_not_the_kinds_name(module):
    code = (REPO_ROOT / "corn_drake" / module).read_text()
    direct = re.findall(r"\b(load_primitive_run|load_run|load_run_with_step|load_student_run"
                        r"\w*|run_kind)\(", code)
    # A run's kind, not an object config's (`scene.object.kind == "library"`).
    named = re.findall(r"\b(?:loaded|run|kind)\.kind (?:==|!=|in|not in) |(?<![.\w])kind (?:==|!=) \"",
                       code)
    assert not direct and not named, (direct, named)
