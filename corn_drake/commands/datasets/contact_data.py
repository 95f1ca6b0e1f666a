"""`corn-drake contact-data`: the contact-pretraining dataset (Algorithm 1 of the paper).

OUT is locked while the command runs. A killed run resumes (finished shards are kept) only with
the same --objects, --num-samples, --eval-samples, --shard-size and --seed, recorded in
OUT/arguments.json; any difference is refused, naming the argument.
"""

from __future__ import annotations

from corn_drake.arguments.value_types import positive_int, seed_int

NAME = "contact-data"
HELP = "generate gripper-contact samples from an object library (sharded, resumable)"


def add_arguments(parser):
    parser.add_argument("--objects", required=True, help="object library folder (manifest.json)")
    parser.add_argument("--num-samples", type=positive_int, required=True, help="training samples")
    parser.add_argument("--eval-samples", type=positive_int, default=None,
                        help="samples for each of val / unseen (default: num-samples / 10)")
    parser.add_argument("--shard-size", type=positive_int, default=4096,
                        help="samples per shard file (a killed run resumes at a shard)")
    parser.add_argument("--seed", type=seed_int, default=0,
                        help="seed of the samples (each shard's from it, its split and index)")
    parser.add_argument("--out", required=True, help="dataset folder, e.g. data/contact")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def output_arguments(args) -> dict:
    """The arguments that define OUT's shards: a resume must repeat them all (every shard is a
    function of the seed, its split and index, and the shard plan)."""
    import os

    from corn_drake.contact.runner import effective_eval_samples

    return {"--objects": os.path.normpath(args.objects), "--num-samples": args.num_samples,
            "--eval-samples": effective_eval_samples(args.num_samples, args.eval_samples),
            "--shard-size": args.shard_size, "--seed": args.seed}


def manifest_arguments(out) -> dict | None:
    """The output arguments a dataset written before arguments.json was kept records in its
    manifest.json (None if it has no readable one)."""
    import os

    from corn_drake.contact.shards import read_manifest

    try:
        m = read_manifest(out)
        splits = m.get("splits", {})
        recorded = {"--objects": os.path.normpath(m["objects_dir"]), "--seed": m["seed"],
                    "--shard-size": m["shard_size"]}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    if "train" in splits:
        recorded["--num-samples"] = splits["train"].get("samples")
    if "val" in splits:
        recorded["--eval-samples"] = splits["val"].get("samples")
    return recorded


def run(args) -> int:
    from corn_drake.contact.runner import generate_dataset
    from corn_drake.run_folders.guards import lock_folder, resume_arguments

    from corn_drake.assets.library import list_objects
    from corn_drake.errors import InputError

    # The input before the output folder is claimed: a missing library is the mistake to name.
    if not list_objects(args.objects, "train"):
        raise InputError(f"object library {args.objects} has no train objects")
    with lock_folder(args.out):
        resume_arguments(args.out, output_arguments(args), made_by=NAME,
                         legacy=manifest_arguments)
        manifest = generate_dataset(args.objects, args.out, args.num_samples, args.seed,
                                    args.eval_samples, args.shard_size, not args.no_progress)
    for split, stats in manifest["splits"].items():
        print(f"{split}: {stats['samples']} samples, positive fraction "
              f"{stats['positive_sample_fraction']:.2f}")
    print(f"wrote {args.out}")
    return 0
