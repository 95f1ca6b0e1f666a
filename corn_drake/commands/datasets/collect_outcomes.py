"""`corn-drake collect-outcomes`: lookahead data for an outcome model (rl/primitive/outcome/
collect.py): at every state of episodes on a library's training objects, each candidate
primitive of a run's policy simulated from that state, with what it did to the object. In this
process, or on `--workers N` Ray workers (local cores, or a cluster with --ray-address:
rl/workers/outcome_workers.py), which write the same files.

One file per --chunk episodes (OUT/episodes_KKKKK.npz, K its first episode), each written
atomically; a rerun skips the files already there, so a stopped collection resumes, and
processes with other --start values can fill one folder side by side. Episode k runs on the
k-th training object with seed 5000 + k, whichever process runs it.
"""

from __future__ import annotations

from pathlib import Path

from corn_drake.arguments.value_types import nonnegative_int, positive_int

NAME = "collect-outcomes"
HELP = "collect lookahead states with every candidate primitive's measured outcome (for fit-outcome)"


def _probability(text: str) -> float:
    import argparse

    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {text!r}")
    return value


def add_arguments(parser):
    from corn_drake.arguments.episode_workers import add_episode_workers

    parser.add_argument("run", type=Path, help="the primitive run (or shipped folder) whose "
                                               "policy proposes the candidates")
    parser.add_argument("--objects", default="data/library",
                        help="object library: episodes cycle through its training objects")
    parser.add_argument("--episodes", type=positive_int, default=120,
                        help="episodes to collect, from --start on")
    parser.add_argument("--start", type=nonnegative_int, default=0,
                        help="the first episode's index (a later round's episodes follow an "
                             "earlier one's: other seeds and objects)")
    parser.add_argument("--chunk", type=positive_int, default=10, help="episodes per file")
    parser.add_argument("--random-motions", type=nonnegative_int, default=2,
                        help="uniform random motions per usable location, besides the actor's")
    parser.add_argument("--follow-policy", type=_probability, default=0.5,
                        help="probability that an episode goes on with the policy's own "
                             "primitive rather than the lookahead's best")
    parser.add_argument("--at-rest", action="store_true",
                        help="success needs the object still at the end of a primitive "
                             "(primitive.success_at_rest)")
    parser.add_argument("--settle-steps", type=nonnegative_int, default=0,
                        help="the executor waits up to this many periods after each primitive "
                             "for the object to come to rest (primitive.settle_steps)")
    parser.add_argument("--set", action="append", default=[], dest="set", metavar="KEY=VALUE",
                        help="env.* / primitive.* setting of the collecting env, as evaluate's "
                             "(e.g. primitive.max_primitives=5; default: none, the run's own)")
    add_episode_workers(parser, "collecting chunks (the files are the same either way)")
    parser.add_argument("--out", type=Path, required=True, help="the data folder")


def run(args) -> int:
    import json

    import torch

    from corn_drake.arguments.episode_workers import check_ray_address
    from corn_drake.rl.primitive.outcome.collect import (collect_chunks, prepare_collection,
                                                         write_chunk)
    from corn_drake.rl.runs.kinds import require_kind

    check_ray_address(args)
    # The proposing run through the registry of run kinds: another kind is named as such.
    require_kind(str(args.run), "primitive", flag="RUN", needs="`collect-outcomes`")

    # One thread: collections run as many one-core processes side by side (16 on the lent
    # machine), and the per-state network calls are too small to gain from more.
    torch.set_num_threads(1)
    settings = (args.run, args.objects, args.episodes, args.out, args.start, args.chunk,
                args.random_motions, args.follow_policy, args.at_rest, args.settle_steps, args.set)
    if not args.workers:
        written = collect_chunks(*settings, log=lambda line: print(line, flush=True))
    else:
        from corn_drake.rl.workers.cluster import pack_objects
        from corn_drake.rl.workers.outcome_workers import collect_on_workers
        from corn_drake.rl.workers.ray_workers import init_ray

        collection = prepare_collection(*settings)
        written = []

        def done(first, arrays, rows):
            for row in rows:
                print(json.dumps(row), flush=True)
            written.append(write_chunk(collection.out, first, arrays))

        if collection.chunks:
            init_ray(args.ray_address or None)
            collect_on_workers(collection, pack_objects(collection.objects, collection.ids),
                               args.workers, done)
    print(f"wrote {len(written)} file(s) to {args.out} (files already there were kept)")
    return 0
