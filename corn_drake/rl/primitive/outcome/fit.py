"""Fitting an outcome model to lookahead data (`corn-drake fit-outcome`): a model file, and/or a
run folder that chooses by the model (config `chooser: outcome_model`) and that `evaluate`,
`ship` and `gallery` read like any primitive run.

Every input is checked before the fit (the proposing run loads, `task` and `sets` apply, the
data hold outcomes, `objects` is within their objects, the run folder is new), so a refused
call writes nothing; both outputs are written atomically.
"""

from __future__ import annotations

from pathlib import Path

from corn_drake.errors import InputError


def fit_outcome(run, data_folders: list, out=None, out_run=None, task: str | None = None,
                sets=(), inputs: str = "raw", seed: int = 0, objects: int | None = None,
                updates: int = 2000, tokens: bool = False) -> dict:
    """Fits the outcome model (model.fit_model, `updates` updates, `seed`, reading `inputs`) to
    every state of `data_folders` (collect folders; with `objects`, the states of that many
    objects only: data.first_objects) and writes it as `out` (a model file) and/or `out_run`
    (run folder `run` with the model as its chooser, `task` and `sets` applied to its config as
    `corn-drake evaluate` applies them). Returns the facts the model file records."""
    from corn_drake.rl.primitive.outcome.data import first_objects, load_outcome_data
    from corn_drake.rl.primitive.outcome.model import INPUT_KINDS, fit_model
    from corn_drake.rl.primitive.outcome.model_file import save_outcome_model
    from corn_drake.rl.primitive.outcome.run_folder import outcome_run_config, write_outcome_run

    if out is None and out_run is None:
        raise InputError("give --out (a model file) and/or --out-run (a run folder that "
                         "chooses by it)")
    if inputs not in INPUT_KINDS:
        raise InputError(f"--inputs {inputs!r}: one of {', '.join(INPUT_KINDS)}")
    if updates < 1:
        raise InputError(f"--updates {updates}: must be >= 1")
    out_run = Path(out_run) if out_run is not None else None
    if out_run is not None and out_run.exists():
        raise InputError(f"--out-run {out_run}: exists; choose a new folder")
    # Before the fit: the run must load and the overrides apply.
    run_cfg = outcome_run_config(Path(run), task, list(sets)) if out_run is not None else None
    data = load_outcome_data(data_folders)
    if objects is not None:
        data = first_objects(data, objects)
    facts = {"states": int(len(data["features_tokens"])), "rows": int(len(data["reward"])),
             "data": [str(d) for d in data_folders], "updates": updates, "seed": seed,
             "proposing_run": str(run), "input_kind": inputs}
    if objects is not None:
        facts["objects"] = objects
    history = []  # the learning curve: a shipped folder's training_history.json
    model = fit_model(data, tokens, updates, seed, history, inputs)
    facts["fit_history"] = history
    if out is not None:
        save_outcome_model(out, model, tokens, **facts)
    if out_run is not None:
        write_outcome_run(Path(run), run_cfg, model, tokens, facts, out_run)
    return facts
