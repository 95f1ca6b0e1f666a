"""`corn-drake fit-chooser`: the learned 6D chooser (rl/imitation/) fitted to the expert's labels
(`corn-drake label`), written as a run folder that `evaluate`, `ship` and `gallery` read like any
primitive run (config `chooser: expert_value`; the labels' proposing run's config, actor and
outcome model, and chooser_value.pt).

The labelled states are rebuilt on --objects (rl/imitation/dataset.py) and kept in --cache, so a
second fit on the same labels starts at once. `--validate` names labels of other objects (the
gate's expert labels on unseen objects, with --validate-objects): how often the fitted chooser
picks the expert's candidate there, and the one-step reward of its picks, are printed and kept
in the model file. The same labels, --seed, --updates and settings give the same weights.
"""

from __future__ import annotations

from pathlib import Path

from corn_drake.arguments.value_types import nonnegative_int, positive_int
from corn_drake.errors import InputError

NAME = "fit-chooser"
HELP = "fit the learned 6D chooser to the expert's labels: a run folder that chooses by it"


def add_arguments(parser):
    parser.add_argument("--labels", type=Path, nargs="+", required=True,
                        help="labels files or folders of them (models/labels/full6d)")
    parser.add_argument("--objects", type=Path, required=True,
                        help="the object library the labels were made on")
    parser.add_argument("--out-run", type=Path, required=True,
                        help="the new run folder (refused if it exists)")
    parser.add_argument("--validate", type=Path, nargs="*", default=[],
                        help="labels of other objects to measure the fit on (default: none)")
    parser.add_argument("--validate-objects", type=Path, default=None,
                        help="the library of the --validate labels (default: --objects)")
    parser.add_argument("--tokens", action="store_true",
                        help="the network reads the location's CORN patch token too")
    parser.add_argument("--updates", type=positive_int, default=4000,
                        help="Adam updates of 256 candidates each")
    parser.add_argument("--seed", type=nonnegative_int, default=0, help="the fit's seed")
    parser.add_argument("--held-out", type=float, default=0.2,
                        help="share of the labels' objects held out of the fit to stop it: the "
                             "weights kept are those that picked best there (0: every object "
                             "fitted, the last weights kept)")
    parser.add_argument("--beam", type=positive_int, default=4,
                        help="candidates of most predicted reward the value chooses among "
                             "(the expert's beam)")
    parser.add_argument("--bank", type=nonnegative_int, default=2,
                        help="fixed uniform motions tried at every usable location besides "
                             "the run's own (the expert's labels: 2 random ones)")
    parser.add_argument("--cache", type=Path, default=Path("data/label_features"),
                        help="where the rebuilt states' features are kept, by labels file")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _proposer(files: list[Path]) -> tuple[str, str]:
    """(the proposing run, the task) every labels file names, or an error naming the odd one."""
    from corn_drake.rl.planner.labels import read_labels

    found = {}
    for path in files:
        settings = read_labels(path)[0]
        found[path] = (settings["planner"]["policy"], settings["task"])
    if len(set(found.values())) != 1:
        raise InputError("--labels: files of other proposing runs or tasks: " + "; ".join(
            f"{p}: {run}, {task}" for p, (run, task) in found.items()))
    return next(iter(found.values()))


def run(args) -> int:
    import dataclasses
    import hashlib

    import torch

    from corn_drake.rl.imitation.dataset import label_files, load_label_arrays
    from corn_drake.rl.imitation.fit import agreement, fit_value, split_objects
    from corn_drake.rl.primitive.value_chooser.value_model import MODEL_FILE, save_value_model
    from corn_drake.rl.planner.sources import policy_run_folder
    from corn_drake.rl.primitive.outcome.model import MODEL_FILE as OUTCOME_FILE
    from corn_drake.rl.primitive.outcome.model_file import load_outcome_parts
    from corn_drake.rl.primitive.outcome.run_folder import outcome_run_config, write_outcome_run

    if args.out_run.exists():
        raise InputError(f"--out-run {args.out_run}: exists; give a new folder")
    if not 0.0 <= args.held_out < 1.0:
        raise InputError(f"--held-out {args.held_out}: a share of the objects, in [0, 1)")
    files = label_files(args.labels)
    proposer, task = _proposer(files)
    run_folder = policy_run_folder(proposer)
    torch.set_num_threads(1)  # as every fit: another thread count sums in another order
    data = load_label_arrays(files, args.objects, args.cache, progress=not args.no_progress)
    history: list = []
    stop = args.held_out > 0 and len(set(data["object"])) >= 2
    if args.held_out > 0 and not stop:
        print("one object's labels: nothing to hold out, the fit runs all its updates")
    fitted, held = split_objects(data, args.held_out, args.seed) if stop else (data, None)
    model = fit_value(fitted, args.tokens, args.updates, args.seed, history=history, held=held,
                      beam=args.beam)
    facts = {"tokens": args.tokens, "beam": args.beam, "bank": args.bank,
             "updates": args.updates, "seed": args.seed, "proposer": proposer,
             "states": int(len(data["chosen"])),
             "searched_states": int((data["chosen"] >= 0).sum()),
             "rows": int(len(data["reward"])),
             "objects": int(len(set(data["object"]))),
             "labels": {str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in files},
             "held_out": args.held_out,
             "held_out_objects": sorted(set(held["object"])) if held is not None else [],
             "kept_update": getattr(model, "kept_update", args.updates),
             "train_agreement": agreement(model, fitted, args.tokens, args.beam),
             "fit_history": history}
    if args.validate:
        validation = load_label_arrays(args.validate, args.validate_objects or args.objects,
                                       args.cache, progress=not args.no_progress)
        facts["validation"] = {"labels": [str(p) for p in label_files(args.validate)],
                               **agreement(model, validation, args.tokens, args.beam)}
    cfg = dataclasses.replace(outcome_run_config(run_folder, task, []), chooser="expert_value")
    # The proposing run's outcome model goes along as it is (its facts and curve with it).
    outcome = load_outcome_parts(run_folder / OUTCOME_FILE)
    kept = {k: v for k, v in outcome.facts.items() if k not in ("tokens", "inputs")}
    write_outcome_run(run_folder, cfg, outcome.model, outcome.facts["tokens"], kept,
                      args.out_run,
                      more={MODEL_FILE: lambda path: save_value_model(path, model, **facts)})
    if held is not None:
        print(f"held out {len(facts['held_out_objects'])} of {facts['objects']} objects; kept the "
              f"weights of update {facts['kept_update']} of {args.updates} (0: the prior alone)")
    print(f"labels of {facts['states']} states ({facts['searched_states']} searched, the rest "
          f"reached by the search's beam; {facts['rows']} candidates, {facts['objects']} "
          f"objects); wrote {args.out_run}")
    for name in ("train_agreement", "validation"):
        if name in facts:
            m = facts[name]
            print(f"{name.replace('_', ' ')}: picks the expert's candidate at "
                  f"{m['agreement']:.2f} of {m['states']} states; one-step reward of its picks "
                  f"{m['pick_reward']:.3f} (the expert's {m['expert_reward']:.3f}, the best "
                  f"{m['best_reward']:.3f})")
    print(f"`corn-drake evaluate --run {args.out_run} ...` chooses by it")
    return 0
