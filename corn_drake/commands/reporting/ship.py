"""`corn-drake ship`: copy a trained teacher, student or contact-primitive policy into a
self-contained weights folder with its card.

    corn-drake ship --run runs/push_corn --report reports/eval_push_corn_unseen.json \
        --library-command "corn-drake objects --num-objects 80 --seed 0 --split unseen --out data/library_unseen" \
        --out models/weights/push_corn

OUT is what `corn-drake evaluate --run OUT` and `distill --run OUT` read, and nothing more:

- config.yaml: the run's config, its encoder named relative to OUT (rl/checkpoints.py
  run_encoder_path) and its object library replaced by the library command's --out;
- checkpoints/last.pt: the agent's weights only (no optimiser, RNG or history: a shipped folder
  evaluates and teaches; `train` does not resume it). A student (a `distill` run) ships its
  {"kind": "student", "student": ...} weights, which hold its encoder, and its config keeps the
  teacher it was distilled from as recorded. A contact-primitive run (`train --policy
  primitive`) ships its actor and critic; its replay files (checkpoints/replay_*.npz, hundreds
  of MB, only for resuming) and its TD3 targets and optimisers stay behind; one that chooses by
  an outcome model (config `chooser: outcome_model`) ships its outcome_model.pt too, and its
  card adds `chooser` and the model's facts (`outcome_model`); where a sibling weights folder
  holds its very actor and critic, its config names that folder (`agent_weights`) instead of
  a copy;
- encoder.pt: the frozen encoder the policy reads (corn, pn, p2v-lite, rot), copied;
- card.json: `policy`, `task`, `env_steps`, `success_rate` and `episodes` of `--report` (an
  `evaluate` report of this very run on the unseen split, kept beside the results), the
  `library_command` that rebuilds those objects and the `library_seed`, `evaluate_command`,
  `train_command` (as given), `source_run`, and the file sizes. A primitive card adds
  `env_steps_unit: primitives`: its env_steps counts primitives (one decision each, many policy
  periods), not the dense policies' policy periods.

The report must be of this run or of OUT (its `run` field: the same weights), on unseen objects
and without overrides, so a card cannot quote another policy's or another task's number; a
student's card also names the report's perception chain (`perception`). It must have measured
the weights that ship (its `checkpoint` and `env_steps`), and be whole: a partial report
(`complete: false`) ships only with --allow-partial, and its card then says `complete: false`.
The checks and the packing live in evaluation/shipping.py; this module parses the flags.
"""

from __future__ import annotations

import shlex
from pathlib import Path

NAME = "ship"
HELP = ("copy a trained teacher, student or contact-primitive run into a self-contained weights "
        "folder with a JSON card")


def add_arguments(parser):
    parser.add_argument("--run", required=True,
                        help="the `corn-drake train` (teacher, or --policy primitive) or "
                             "`distill` (student) run folder")
    parser.add_argument("--report", required=True,
                        help="`corn-drake evaluate` report of this run on the unseen split")
    parser.add_argument("--library-command", required=True,
                        help="the `corn-drake objects` command that rebuilds the evaluated "
                             "objects (its --out becomes the shipped config's library)")
    parser.add_argument("--allow-partial", action="store_true",
                        help="ship a partial --report (complete: false, an interrupted "
                             "evaluate); the card then says complete: false (default: refused)")
    parser.add_argument("--train-command", default="",
                        help="the command that trained the run, recorded on the card (default: none)")
    parser.add_argument("--out", required=True, help="weights folder, e.g. models/weights/push_corn")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace whatever --out holds (default: only a new or empty folder, "
                             "or the weights shipped from the same --run, is written)")


def library_arguments(command: str) -> dict[str, str]:
    """The flags a `corn-drake objects` command line names, {"--flag": value as written, or
    True for a switch such as --keep-size}, read by that command's own parser (so a switch is
    not taken for a flag's value); anything it refuses, or a missing --out, is an InputError
    naming --library-command."""
    import argparse

    from corn_drake.commands.datasets import objects
    from corn_drake.errors import InputError

    words = shlex.split(command)
    if words[:2] != ["corn-drake", "objects"]:
        raise InputError(f"--library-command must be a `corn-drake objects ...` command, got "
                         f"{command!r}")

    class Parser(argparse.ArgumentParser):
        def error(self, message):
            if "--out" in message:
                raise InputError(f"--library-command {command!r} has no --out")
            raise InputError(f"--library-command {command!r}: {message}")

    parser = Parser(prog="corn-drake objects", add_help=False)
    objects.add_arguments(parser)
    for action in parser._actions:  # only what the command line names
        action.default = argparse.SUPPRESS
    named = vars(parser.parse_args(words[2:]))
    flags = {a.dest: a.option_strings[0] for a in parser._actions if a.option_strings}
    raw = {flags[dest]: value for dest, value in named.items()}
    # As written (a string), so the card's command and the rebuilt one compare as text.
    return {flag: value if isinstance(value, bool) else _as_written(words, flag, value)
            for flag, value in raw.items()}


def _as_written(words: list[str], flag: str, parsed) -> str:
    for i, word in enumerate(words):
        if word == flag and i + 1 < len(words):
            return words[i + 1]
        if word.startswith(flag + "="):
            return word.split("=", 1)[1]
    return str(parsed)


def with_hull_budget(command: str, library: dict[str, str]) -> str:
    """`command` (a library command, parsed as `library`) naming its hull budget: the card's
    command must rebuild exactly its objects whatever `objects`' default becomes, so a command
    without --max-hulls gets the one its library was built with (its arguments.json; libraries
    recorded before the flag existed were built with 16). A command naming another budget than
    its library's is an InputError."""
    from corn_drake.commands.datasets.objects import UNRECORDED_MAX_HULLS
    from corn_drake.errors import InputError
    from corn_drake.run_folders.guards import read_recorded_arguments

    recorded = (read_recorded_arguments(library["--out"]) or {}).get("--max-hulls",
                                                                      UNRECORDED_MAX_HULLS)
    named = library.get("--max-hulls")
    if named is None:
        return f"{command} --max-hulls {recorded}"
    if str(named) != str(recorded):
        raise InputError(f"--library-command names --max-hulls {named}, but "
                         f"{library['--out']} was built with {recorded}")
    return command


def run(args) -> int:
    from corn_drake.evaluation.shipping import read_report, ship

    # The report first (cheapest, and the commonest mistake), then the library command; the
    # run is loaded and every check made before OUT is (evaluation/shipping.py).
    from corn_drake.storage.output_owners import check_folder_owner

    check_folder_owner(Path(args.out), str(args.run), args.overwrite)
    report = read_report(args.report, (args.run, args.out), args.allow_partial)
    library = library_arguments(args.library_command)
    card = ship(args.run, args.out, report, args.report,
                with_hull_budget(args.library_command, library), library["--out"],
                int(library.get("--seed", 0)), args.train_command)
    partial = "" if card.get("complete", True) else " (partial report: complete false)"
    print(f"shipped {args.run} to {Path(args.out)}: {card['policy']} on {card['task']}, "
          f"{card['env_steps']} {card.get('env_steps_unit', 'steps')}, unseen success "
          f"{card['success_rate']:.3f} over {card['episodes']} episodes{partial}; "
          f"{sum(card['bytes'].values()) / 1e6:.1f} MB")
    return 0
