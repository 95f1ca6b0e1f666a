"""`corn-drake curves`: one learning-curve PNG over several training runs (e.g. corn vs state).

Each run's history comes from its checkpoint (present while the run is still going or was
killed) or, failing that, its metrics.json. Runs are labelled by their policy and task, from
the run's config.yaml.
"""

from __future__ import annotations

from pathlib import Path

from corn_drake.errors import InputError, MissingInputError

NAME = "curves"
HELP = "plot success rate and return of several training runs on one figure"


def add_arguments(parser):
    parser.add_argument("--run", action="append", required=True, dest="runs",
                        help="run folder written by `corn-drake train` (repeat for each run)")
    parser.add_argument("--out", required=True, help="PNG path")
    parser.add_argument("--x", choices=("steps", "hours"), default="steps",
                        help="x axis: env steps, or training hours (each update's steps over its "
                             "steps/s, summed: the time on the machine it ran on; see --rate)")
    parser.add_argument("--rate", choices=("median", "recorded"), default="median",
                        help="with --x hours and --summary: charge every update at the run's "
                             "median steps/s (steady when the core was shared for a while) or at "
                             "the steps/s it recorded")
    parser.add_argument("--rates", default="",
                        help="a `corn-drake bench policies` report: charge each run at its "
                             "policy's training steps/s there (same-run, quiet-machine rates) "
                             "instead of --rate (default: none, --rate)")
    parser.add_argument("--summary", default="",
                        help="JSON path: each run's final step and hours, and every run at the "
                             "shortest run's training time (its step, training success there) (default: none)")
    parser.add_argument("--history", default="",
                        help="JSON path: each run's folder and every update's history row (the "
                             "numbers the figure plots), kept beside the figure since a run "
                             "folder may not outlive the machine it ran on (default: none)")


def run_history(run_dir: Path) -> tuple[str, list[dict]]:
    """(label, history rows) of one training run; a clear error when it has neither file."""
    checkpoint = run_dir / "checkpoints" / "last.pt"
    metrics = run_dir / "metrics.json"
    from corn_drake.storage.atomic_files import read_json
    from corn_drake.storage.checkpoint_files import load_checkpoint

    state = load_checkpoint(checkpoint, required=("history",))  # prev.pt if last.pt is unreadable
    if state is not None:
        history = state["history"]
    elif metrics.is_file():
        written = read_json(metrics, "training metrics")
        history = written.get("history") if isinstance(written, dict) else None
        if not isinstance(history, list):
            raise InputError(f"{metrics} has no 'history' list (written before curves were kept?)")
    else:
        raise MissingInputError(f"{run_dir}: no checkpoints/last.pt or metrics.json; is it a training run?")
    from corn_drake.run_folders.config_file import load_run_config, run_config_path

    label = run_dir.name
    if run_config_path(run_dir).is_file():
        cfg = load_run_config(run_dir)
        label = f"{cfg.policy} on {cfg.env.task.name} ({run_dir.name})"
    return label, history


def benchmarked_rates(path: str) -> dict[str, float]:
    """policy -> training steps/s of a `corn-drake bench policies` report."""
    from corn_drake.storage.atomic_files import read_json

    report = read_json(path, "bench policies report")
    is_policies = isinstance(report, dict) and report.get("benchmark") == "policies"
    rates = report.get("results", {}).get("train_steps_per_s") if is_policies else None
    if not isinstance(rates, dict):
        raise InputError(f"--rates {path}: not a `corn-drake bench policies` report")
    return rates


def run_policy(run_dir: Path) -> str | None:
    from corn_drake.run_folders.config_file import load_run_config, run_config_path

    return load_run_config(run_dir).policy if run_config_path(run_dir).is_file() else None


def run(args) -> int:
    from corn_drake.storage.atomic_files import ensure_writable, write_json
    from corn_drake.viz.learning_curves import at_equal_time, plot_learning_curves, training_hours

    for path, argument in ((args.summary, "--summary"), (args.history, "--history")):
        if path:
            ensure_writable(Path(path).parent, argument)
    benchmarked = benchmarked_rates(args.rates) if args.rates else None
    runs, folders, rates = {}, {}, {}
    for r in args.runs:
        label, history = run_history(Path(r))
        if label in runs:
            label = f"{label} [{len(runs)}]"  # the same run twice stays two lines
        runs[label], folders[label] = history, str(Path(r).resolve())
        rates[label] = args.rate
        if benchmarked is not None:
            policy = run_policy(Path(r))
            if policy not in benchmarked:
                raise InputError(f"--rates {args.rates} has no rate for run {r}'s policy "
                                 f"{policy!r} (it has {', '.join(benchmarked)})")
            rates[label] = benchmarked[policy]
        if history and (args.x == "hours" or args.summary):
            try:
                training_hours(history, rates[label])
            except ValueError as e:
                raise InputError(f"--run {r}: no training time can be read from its history ({e})") from None
    for label, history in runs.items():
        last = history[-1] if history else {}
        print(f"{label}: {last.get('step', 0)} steps, success {last.get('success_rate', 0.0):.2f}")
    plot_learning_curves(runs, Path(args.out), x=args.x, rates=rates)
    print(f"wrote {args.out}")
    if args.history:
        write_json(Path(args.history), {"runs": {label: {"run": folders[label], "history": history}
                                                 for label, history in runs.items()}})
        print(f"wrote {args.history}")
    if args.summary:
        equal = at_equal_time(runs, rates)
        for label, row in equal["runs"].items():
            row["run"] = folders[label]  # what `corn-drake compare` matches reports to
        print(f"at the shortest run's {equal['hours']:.2f} training hours: " + "; ".join(
            f"{label} step {row['step']} success {row['training_success_rate']:.2f}"
            for label, row in equal["runs"].items()))
        write_json(Path(args.summary), {"runs_at_equal_time": equal,
                                        "runs": [str(r) for r in args.runs]})
        print(f"wrote {args.summary}")
    return 0
