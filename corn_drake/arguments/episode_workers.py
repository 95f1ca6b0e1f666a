"""`--workers N` and `--ray-address` for the commands that spread whole episodes (or chunks of
them) over Ray workers: `evaluate --run planner`, `label`, `collect-outcomes`. One wording and
one check for all three (the trainers' own --workers is run_flags.py's: rollout workers)."""

from corn_drake.arguments.value_types import nonnegative_int


def add_episode_workers(parser, doing: str, only: str = "") -> None:
    """The two flags; `doing` says what each worker does ("labelling episodes"), `only` which
    runs take them ("--run planner only: ")."""
    parser.add_argument("--workers", type=nonnegative_int, default=0,
                        help=f"{only}Ray workers {doing} side by side (0: in this process)")
    parser.add_argument("--ray-address", default="",
                        help=f"{only}a Ray cluster's address for --workers (default: a Ray of "
                             "this process's own on this machine's cores)")


def check_ray_address(args) -> None:
    """--ray-address names where the workers run: without --workers there are none."""
    from corn_drake.errors import InputError

    if args.ray_address and not args.workers:
        raise InputError("--ray-address needs --workers N (the workers it runs on the cluster)")
