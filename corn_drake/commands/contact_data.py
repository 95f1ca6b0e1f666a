"""`corn-drake contact-data`: the contact-pretraining dataset (Algorithm 1 of the paper)."""

from __future__ import annotations

from corn_drake.cli_types import nonnegative_int, positive_int

NAME = "contact-data"
HELP = "generate gripper-contact samples from an object library (sharded, resumable)"


def add_arguments(parser):
    parser.add_argument("--objects", required=True, help="object library folder (manifest.json)")
    parser.add_argument("--num-samples", type=positive_int, required=True, help="training samples")
    parser.add_argument("--eval-samples", type=positive_int, default=None,
                        help="samples for each of val / unseen (default: num-samples / 10)")
    parser.add_argument("--shard-size", type=positive_int, default=4096)
    parser.add_argument("--seed", type=nonnegative_int, default=0)
    parser.add_argument("--out", required=True)
    parser.add_argument("--no-progress", action="store_true")


def run(args) -> int:
    from corn_drake.contact.runner import generate_dataset

    manifest = generate_dataset(args.objects, args.out, args.num_samples, args.seed,
                                args.eval_samples, args.shard_size, not args.no_progress)
    for split, stats in manifest["splits"].items():
        print(f"{split}: {stats['samples']} samples, positive fraction "
              f"{stats['positive_sample_fraction']:.2f}")
    print(f"wrote {args.out}")
    return 0
