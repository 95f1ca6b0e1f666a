"""`corn-drake fit-outcome`: an outcome model (rl/primitive/outcome/model.py) fitted to every
state of `collect-outcomes` folders, written as a model file (--out) and/or a run folder that
chooses by it (--out-run: RUN's config and actor, which proposes the motions, with the model
as its outcome_model.pt and `chooser: outcome_model`; `--task` and `--set` applied to its config
as `corn-drake evaluate` applies them). `evaluate`, `ship` and `gallery` read that folder like
any primitive run; the file keeps the fit's learning curve (`fit_history`), which `ship` writes
as the shipped folder's training_history.json.

The same data, --seed, --inputs, --updates and --objects give the same weights, bit for bit.
"""

from __future__ import annotations

from pathlib import Path

from corn_drake.arguments.value_types import nonnegative_int, positive_int

NAME = "fit-outcome"
HELP = "fit an outcome model to collect-outcomes data: a model file and/or a run that chooses by it"


def add_arguments(parser):
    from corn_drake.config.choices import OUTCOME_INPUT_KINDS

    parser.add_argument("run", type=Path,
                        help="the primitive run (or shipped folder) whose actor proposes motions")
    parser.add_argument("--data", type=Path, nargs="+", required=True,
                        help="collect-outcomes folders (object ids told apart by the folder's "
                             "position: libraries of other seeds reuse them)")
    parser.add_argument("--out", type=Path, default=None,
                        help="the model file (default: none; give it and/or --out-run)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace the file --out names (default: a new path only)")
    parser.add_argument("--out-run", type=Path, default=None,
                        help="a new run folder that chooses by the model (default: none)")
    parser.add_argument("--task", default=None,
                        help="the run folder's task (as evaluate --task; default: RUN's own)")
    parser.add_argument("--set", action="append", default=[], dest="set", metavar="KEY=VALUE",
                        help="env.* / primitive.* setting of the run folder (as "
                             "evaluate's; default: none, RUN's own)")
    parser.add_argument("--inputs", choices=OUTCOME_INPUT_KINDS, default="raw",
                        help="what the model reads: the candidate's own numbers (raw) or "
                             "object-relative ones (box_contact)")
    parser.add_argument("--seed", type=nonnegative_int, default=0,
                        help="the fit's seed (how far one fit lands from another on the same "
                             "data)")
    parser.add_argument("--objects", type=positive_int, default=None,
                        help="fit on the states of this many objects only, the first of one "
                             "fixed order (a learning curve over objects; default: every "
                             "object)")
    parser.add_argument("--updates", type=positive_int, default=2000,
                        help="Adam updates of 256 candidates each")
    parser.add_argument("--tokens", action="store_true",
                        help="the model reads the location's patch token too")


def run(args) -> int:
    import torch

    from corn_drake.rl.primitive.outcome.fit import fit_outcome
    from corn_drake.rl.runs.kinds import require_kind

    # The proposing run through the registry of run kinds: another kind is named as such.
    require_kind(str(args.run), "primitive", flag="RUN", needs="`fit-outcome`")

    from corn_drake.storage.output_owners import check_new_file

    check_new_file(args.out, args.overwrite)  # before the fit: a refused fit costs nothing
    # One thread, as every shipped fit ran: another thread count may sum in another order and
    # land on other weights.
    torch.set_num_threads(1)
    facts = fit_outcome(args.run, args.data, out=args.out, out_run=args.out_run, task=args.task,
                        sets=args.set, inputs=args.inputs, seed=args.seed,
                        objects=args.objects, updates=args.updates, tokens=args.tokens)
    for path in (args.out, args.out_run):
        if path is not None:
            print(f"wrote {path}")
    if args.out_run is not None:
        print(f"`corn-drake evaluate --run {args.out_run} ...` chooses by the model")
    print(f"fitted to {facts['states']} states, {facts['rows']} candidates")
    return 0
