"""The flags `train` and `distill` share, and the table from each flag to the run setting it sets
(config/training.RunSettings), so the two commands spell and document them once.

Every shortcut flag defaults to None: a new run takes the field's default, a resumed run its
recorded value, and a flag given on a resume is an override checked against the recording.
"""

from __future__ import annotations

from corn_drake.arguments.value_types import nonnegative_int, positive_int, seed_int

# argparse dest -> the RunSettings field it sets.
RUN_SHORTCUTS = {"steps": "total_steps", "workers": "workers", "envs_per_worker": "envs_per_worker",
                 "seed": "seed", "encoder": "encoder", "allow_weak_encoder": "allow_weak_encoder",
                 "ray_address": "ray_address", "device": "device"}
# On a resume total_steps may grow (the run is extended); where the workers and the learner's
# tensors live, and how often the run checkpoints, do not change what it learns.
RESUME_MAY_GROW = ("total_steps",)
RESUME_MAY_CHANGE = ("ray_address", "device", "checkpoint_every")


def add_run_arguments(parser, command: str, encoder_help: str) -> None:
    """--out, --resume and the RUN_SHORTCUTS flags, for `command` (train or distill)."""
    parser.add_argument("--out", required=True,
                        help="run folder, e.g. runs/NAME; an existing run resumes from its "
                             "config.yaml (no other argument needed)")
    parser.add_argument("--resume", action="store_true",
                        help="OUT must be an existing run (refuses to start a new one, e.g. "
                             "on a mistyped folder)")
    parser.add_argument("--encoder", default=None, help=encoder_help)
    parser.add_argument("--allow-weak-encoder", action="store_true", default=None,
                        help="accept an --encoder below its pretraining bar (contact F1 0.8; "
                             "pretext skill 0.2) or without a record, with a warning")
    parser.add_argument("--steps", type=positive_int, default=None,
                        help="total environment steps (default: 20000)")
    parser.add_argument("--workers", type=nonnegative_int, default=None,
                        help="Ray rollout workers (default 0: in-process)")
    parser.add_argument("--envs-per-worker", type=positive_int, default=None,
                        help="envs each rollout worker steps (in this process with --workers 0) "
                             "(default: 4)")
    parser.add_argument("--seed", type=seed_int, default=None,
                        help="seed of the networks' initialisation and the envs' episodes "
                             "(default: 0)")
    parser.add_argument("--ray-address", default=None,
                        help="connect to a Ray cluster (default: a local one, started with --workers)")
    parser.add_argument("--device", default=None,
                        help="torch device of the learner (its batched inference and updates): "
                             "cpu (default), cuda or cuda:N; the envs run on the CPU")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def flag_of_field(field: str, shortcuts: dict[str, str]) -> str | None:
    """The flag (`--envs-per-worker`) that sets config field `field` ('a.b.c'), or None."""
    for dest, name in shortcuts.items():
        if name == field:
            return "--" + dest.replace("_", "-")
    return None
