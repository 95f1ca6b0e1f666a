"""Every shipped card is a recipe that works today (issue 62): its training command, read by
today's parser and config builder (nothing trained), gives the shipped config.yaml field for
field, but for what `ship` rewrites (the library path, the encoder's and the agent weights'
paths). A default that changed since a policy shipped must be set on its card, or this fails
naming the field. Resumed runs: the last `--steps` of the card's commands is the run's length.

The cards' commands are `train` (PPO teachers and primitive runs), `distill` (the student, on
top of its teacher's config) and `fit-outcome` (an outcome-model folder's config: its proposing
run's, on the task it names)."""

from __future__ import annotations

import dataclasses
import json
import re
import shlex
from pathlib import Path

import pytest

from corn_drake import cli
from tests.paths import REPO_ROOT

WEIGHTS = REPO_ROOT / "models" / "weights"
CARDS = sorted(p.parent.name for p in WEIGHTS.glob("*/card.json"))
# What ship rewrites in the config it packs (evaluation/shipping.py), and so not the recipe's.
SHIP_REWRITES = ("encoder", "env.scene.object.library", "env.teacher.scene.object.library",
                 "agent_weights", "teacher")


def _commands(card: dict) -> list[list[str]]:
    """The card's `corn-drake` commands (its train_command's ';'-separated parts, notes in
    parentheses dropped), as argument lists without the program name."""
    out = []
    for part in re.sub(r"\([^)]*\)", "", card["train_command"]).split(";"):
        words = shlex.split(part.strip())
        if words[:1] == ["then"]:
            words = words[1:]
        if words[:1] == ["corn-drake"]:
            out.append(words[1:])
        elif words[:1] == ["--steps"]:  # "then --steps N": the same command resumed longer
            out.append([*out[-1], *words])
    return out


def _flat(value, prefix: str = "") -> dict:
    if dataclasses.is_dataclass(value):
        value = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {k: v for key, item in value.items() for k, v in _flat(item, prefix + key + ".").items()}
    return {prefix[:-1]: repr(value)}  # Drake's config objects compare by what they print


def _recipe_config(card: dict):
    """(the config the card's first command asks for, its schema)."""
    from corn_drake.commands.learning import distill, train, train_primitive
    from corn_drake.config.plumbing.loader import load_config
    from corn_drake.run_folders.config_file import run_config_path

    commands = _commands(card)
    fits = [c for c in commands if c[0] == "fit-outcome"]
    if fits:  # an outcome-model folder: its proposing run's config on the fit's task
        from corn_drake.config.primitive import PrimitiveTrainConfig
        from corn_drake.rl.primitive.outcome.run_folder import outcome_run_config

        args = cli.build_parser().parse_args(fits[-1])
        return outcome_run_config(REPO_ROOT / args.run, args.task, args.set), PrimitiveTrainConfig
    first = commands[0]
    args = cli.build_parser().parse_args(first)
    steps = [c[len(c) - 1 - c[::-1].index("--steps") + 1] for c in commands if "--steps" in c]
    if first[0] == "distill":
        from corn_drake.config.training import DistillConfig, TrainConfig

        teacher = load_config(TrainConfig, run_config_path(REPO_ROOT / args.teacher))
        cfg = distill.requested_config(args, None, teacher)
        schema = DistillConfig
    elif train_primitive.wants_primitive(args):
        from corn_drake.config.primitive import PrimitiveTrainConfig

        cfg, schema = train_primitive.requested_config(args, None), PrimitiveTrainConfig
    else:
        from corn_drake.config.training import TrainConfig

        cfg, schema = train.requested_config(args, None), TrainConfig
    return dataclasses.replace(cfg, total_steps=int(steps[-1])), schema


@pytest.mark.parametrize("name", CARDS)
def test_the_cards_command_gives_the_shipped_config(name, monkeypatch):
    from corn_drake.config.plumbing.loader import load_config

    monkeypatch.chdir(REPO_ROOT)  # the cards' paths are the repository's
    card = json.loads((WEIGHTS / name / "card.json").read_text())
    requested, schema = _recipe_config(card)
    shipped = load_config(schema, WEIGHTS / name / "config.yaml")
    asked, held = _flat(requested), _flat(shipped)
    differ = {k: (asked.get(k), held.get(k)) for k in set(asked) | set(held)
              if asked.get(k) != held.get(k) and not k.startswith(SHIP_REWRITES)}
    # A stopped run ships an earlier checkpoint than its command's length: the card says so.
    if "total_steps" in differ and "stopped at" in card["train_command"]:
        differ.pop("total_steps")
    assert not differ, f"{name}'s card asks for other settings than it shipped: {differ}"


def test_the_commands_are_read_from_every_card():
    for name in CARDS:
        card = json.loads((WEIGHTS / name / "card.json").read_text())
        assert _commands(card), name


@pytest.mark.parametrize("name", CARDS)
def test_every_step_of_a_card_is_a_command_that_parses_today(name):
    """A card's recipe is product commands only: no script outside the package (the
    full6d_outcome card once began with an experiment's device script), and each `corn-drake`
    step is read by today's parser (a retired flag fails here, naming the card)."""
    card = json.loads((WEIGHTS / name / "card.json").read_text())
    parts = [p.strip() for p in re.sub(r"\([^)]*\)", "", card["train_command"]).split(";")]
    for part in filter(None, parts):
        words = shlex.split(part)
        words = words[1:] if words[:1] == ["then"] else words
        assert words[0] in ("corn-drake", "--steps"), f"{name}: {part!r} is not a corn-drake step"
    parser = cli.build_parser()
    for command in _commands(card):
        try:
            parser.parse_args(command)
        except SystemExit:
            pytest.fail(f"{name}: today's parser refuses {' '.join(command)!r}")


REBUILT = [name for name in CARDS
           if "rebuild" in json.loads((WEIGHTS / name / "card.json").read_text())]


def test_the_push_primitive_card_records_its_rebuild():
    assert "push_primitive" in REBUILT  # issue 62: rebuilt from its card on this kind of machine


@pytest.mark.parametrize("name", REBUILT)
def test_a_rebuild_quotes_its_report_and_lands_inside_the_shipped_interval(name):
    """A card's `rebuild` record: the report its rebuilt weights made on the card's evaluation
    episodes says what the record quotes, and that success lies inside the 95 % Wilson interval
    of the shipped weights' own report (what "the card rebuilds its weights" means here)."""
    from corn_drake.evaluation.episode_rows import wilson

    card = json.loads((WEIGHTS / name / "card.json").read_text())
    rebuild = card["rebuild"]
    report = json.loads((REPO_ROOT / rebuild["report"]).read_text())
    assert report["complete"] and len(report["episodes"]) == card["episodes"]
    assert (report["task"], report["split"]) == (card["task"], card["split"])
    assert rebuild["success_rate"] == report["success_rate"]
    # The same episodes as the shipped report's: object and seed, one by one.
    shipped = json.loads((REPO_ROOT / card["report"]).read_text())
    assert [(e["object"], e["seed"]) for e in report["episodes"]] == \
        [(e["object"], e["seed"]) for e in shipped["episodes"]]
    low, high = wilson(round(card["success_rate"] * card["episodes"]), card["episodes"])
    assert low <= rebuild["success_rate"] <= high, (rebuild["success_rate"], low, high)
    at_rest = rebuild.get("at_rest_rule")
    if at_rest is not None:  # the same weights under the at-rest rule, quoted as measured
        measured = json.loads((REPO_ROOT / at_rest["report"]).read_text())
        assert measured["success_rate"] == at_rest["success_rate"]
        assert measured["weights_sha256"] == report["weights_sha256"]
    steps = rebuild["core_hours"]
    assert steps and all(v > 0 for v in steps.values())
