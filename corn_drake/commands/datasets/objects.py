"""`corn-drake objects`: build an object library (procedural families or a folder of meshes).

OUT is locked while the command runs. Building into an existing library resumes it only with the
--source, --seed, --drops and --max-hulls it was made with (recorded in OUT/arguments.json;
libraries made before the record was kept are not checked, nor --max-hulls in libraries recorded
before it existed: they were built with 16); a procedural --num-objects may grow, adding
objects (a library recorded with the old spelling, --num, resumes the same).
--workers N builds procedural objects in N processes (assets/build_pool.py), the same library.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from corn_drake.arguments.renamed import add_renamed
from corn_drake.arguments.value_types import positive_int, seed_int

if TYPE_CHECKING:
    from corn_drake.assets.manifest import LibraryObject

# CoACD's hull budget per object unless --max-hulls says otherwise (assets/processing/decompose.py). 8 was
# measured and not adopted (the hull-budget study's results): mugs and bowls lose their
# cavities (hull union 1.35-1.78x the mesh) for 10 % more physics speed on those objects.
DEFAULT_MAX_HULLS = 16
# The budget of libraries whose arguments.json predates --max-hulls: they were built with 16.
UNRECORDED_MAX_HULLS = 16

# Arguments a library's arguments.json may record under an older spelling -> the current one.
RECORDED_RENAMES = {"--num": "--num-objects"}

NAME = "objects"
HELP = "build an object library: --source procedural, or --source PATH (OBJ/STL/PLY/GLB/OFF)"


def add_arguments(parser):
    parser.add_argument("--source", default="procedural",
                        help="'procedural' or a mesh folder; each mesh's object id is mesh_ and "
                             "its path's letters and digits (others made _), and a folder whose "
                             "files would share an id (cup a.obj, cup_a.obj; Cup.obj, cup.stl) "
                             "is refused, naming them")
    parser.add_argument("--num-objects", type=positive_int, default=80,
                        help="procedural objects in the full library (train and unseen)")
    add_renamed(parser, "--num", "--num-objects", " (as in `demo`)")
    parser.add_argument("--seed", type=seed_int, default=0,
                        help="seed of the shapes, the train/unseen split and the drops")
    parser.add_argument("--drops", type=positive_int, default=128,
                        help="drops per object for stable poses")
    parser.add_argument("--max-hulls", type=positive_int, default=DEFAULT_MAX_HULLS,
                        help="most convex hulls per object (CoACD max_convex_hull; the authors "
                             "use 16): fewer make contact cheaper to simulate and the shapes "
                             "coarser (the hull-budget study's results)")
    parser.add_argument("--split", choices=("train", "unseen"), default=None,
                        help="procedural only: build just the objects of this split of the full "
                             "--num-objects build, identical to theirs (e.g. the unseen objects to "
                             "evaluate shipped weights on); the same command without --split "
                             "completes the library later (default: both splits)")
    parser.add_argument("--workers", type=positive_int, default=1,
                        help="procedural only: processes building objects side by side, one "
                             "thread each (the library is the same as with 1, byte for byte)")
    parser.add_argument("--keep-size", action="store_true",
                        help="mesh folders only: keep each mesh's real size (the unit read from "
                             "its size and said on screen: metres, millimetres or centimetres) "
                             "instead of rescaling it to the library's 5-10 cm radius, where it "
                             "fits the gripper and table (radius 2-15 cm); a mesh that does not "
                             "is rejected, saying why")
    parser.add_argument("--unit", choices=("auto", "m", "cm", "mm"), default="auto",
                        help="mesh folders only: the unit of the meshes' numbers (default auto: "
                             "read from each mesh's size, the first of metres, millimetres, "
                             "centimetres that makes it 1 cm-1 m across, and said on screen); "
                             "what --keep-size keeps, and what the manifest records")
    parser.add_argument("--out", required=True, help="library folder, e.g. data/library")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def output_arguments(args) -> dict:
    """The arguments that define the library's objects (each a function of the seed and its
    index or file). --num-objects is one only for procedural libraries, and may grow: a resume
    with a larger --num-objects adds objects to the same library."""
    import os

    procedural = args.source == "procedural"
    recorded = {"--source": args.source if procedural else os.path.normpath(args.source),
                "--seed": args.seed, "--drops": args.drops, "--max-hulls": args.max_hulls}
    if procedural:
        recorded["--num-objects"] = args.num_objects
    else:
        recorded["--keep-size"] = bool(args.keep_size)
        if args.unit != "auto":  # recorded only when given: libraries made before it resume
            recorded["--unit"] = args.unit
    return recorded


# How the summary names each unseen group (assets/splits.py's "family" and "member").
UNSEEN_GROUP_WORDS = {"family": "of held-out families", "member": "held-out members of seen families"}


def _split_summary(objects: list[LibraryObject]) -> str:
    """'N train + M unseen objects (k of held-out families, l held-out members of seen
    families)': the unseen count by kind of novelty (assets/splits.py)."""
    from collections import Counter

    splits = Counter(o.split for o in objects)
    groups = Counter(o.unseen_group for o in objects if o.split == "unseen")
    kinds = ", ".join(f"{n} {UNSEEN_GROUP_WORDS.get(g, g)}"
                      for g, n in sorted(groups.items(), key=lambda kv: str(kv[0])))
    return (f"{splits['train']} train + {splits['unseen']} unseen objects"
            + (f" ({kinds})" if kinds else ""))


def _stable_pose_summary(objects: list[LibraryObject]) -> list[str]:
    """Stable poses kept under both contact settings, overall and for each object that lost
    some."""
    checked = [o for o in objects if o.stable_pose_kept_fraction is not None]
    held = sum(o.drops["verified"] for o in checked)
    kept = sum(o.drops["held_second_setting"] for o in checked)
    lines = [f"stable poses holding under both contact settings: {kept} of the {held} holding in "
             f"the training setting ({kept / max(held, 1):.0%})"]
    if len(checked) < len(objects):  # a library resumed from a build before the second setting
        lines[0] += f"; {len(objects) - len(checked)} older objects were not checked"
    for o in checked:
        if o.stable_pose_kept_fraction < 1.0:
            d = o.drops
            lines.append(f"  {o.id}: kept {d['held_second_setting']} of {d['verified']} "
                         f"({o.stable_pose_kept_fraction:.0%})")
    return lines


def run(args) -> int:
    from corn_drake.assets.library import build_procedural, ingest_folder
    from corn_drake.assets.processing.process import ProcessConfig
    from corn_drake.errors import InputError
    from corn_drake.run_folders.guards import lock_folder, resume_arguments

    if args.split is not None and args.source != "procedural":  # before OUT is touched
        raise InputError(f"--split {args.split} builds part of a procedural library; "
                         f"--source {args.source} ingests every mesh of a folder")
    if args.keep_size and args.source == "procedural":
        raise InputError("--keep-size keeps the real size of the meshes of a --source folder; "
                         "procedural shapes have no real size (leave --keep-size out)")
    if args.unit != "auto" and args.source == "procedural":
        raise InputError(f"--unit {args.unit} says the unit of a --source folder's meshes; "
                         "procedural shapes are made in metres (leave --unit out)")
    if args.workers > 1 and args.source != "procedural":  # refused, not silently serial
        raise InputError(f"--workers {args.workers} builds procedural objects side by side; "
                         f"--source {args.source} ingests its meshes one by one (leave "
                         "--workers out)")
    cfg = ProcessConfig()
    cfg.drops.drops = args.drops
    cfg.decomposition.max_convex_hull = args.max_hulls
    cfg.keep_size = args.keep_size
    cfg.unit = args.unit
    with lock_folder(args.out):
        resume_arguments(args.out, output_arguments(args), made_by=NAME,
                         may_grow=("--num-objects",), renamed=RECORDED_RENAMES,
                         holds_own=lambda out: (out / "manifest.json").is_file())
        if args.source == "procedural":
            manifest = build_procedural(args.out, args.num_objects, args.seed, cfg, not args.no_progress,
                                        args.split, workers=args.workers)
        else:
            from tqdm import tqdm

            manifest = ingest_folder(args.source, args.out, args.seed, cfg, not args.no_progress,
                                     say=tqdm.write)  # each mesh's size rule, above the bar
    print(_split_summary(manifest.objects) + f", {len(manifest.rejected)} rejected; "
          f"manifest {args.out}/manifest.json")
    print("\n".join(_stable_pose_summary(manifest.objects)))
    for r in manifest.rejected:
        print(f"  rejected {r.source}: {r.reason}")
    if not manifest.objects and manifest.rejected:
        # Every mesh refused: a library of nothing is no result (the reasons are listed above).
        raise InputError(f"--source {args.source}: none of its {len(manifest.rejected)} meshes "
                         f"became an object (each rejection is listed above); {args.out} holds "
                         "no object to train or evaluate on")
    splits = {o.split for o in manifest.objects}
    if manifest.objects and len(splits) == 1:  # e.g. a folder of a few meshes: all train
        print(f"every object is {splits.pop()}: evaluate them with `corn-drake evaluate --objects "
              f"{args.out} --split all`")
    return 0
