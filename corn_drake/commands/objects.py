"""`corn-drake objects`: build an object library (procedural families or a folder of meshes)."""

from __future__ import annotations

from corn_drake.cli_types import nonnegative_int, positive_int

NAME = "objects"
HELP = "build an object library: --source procedural, or --source PATH (OBJ/STL/PLY/GLB/OFF)"


def add_arguments(parser):
    parser.add_argument("--source", default="procedural", help="'procedural' or a mesh folder")
    parser.add_argument("--num", type=positive_int, default=80, help="procedural objects")
    parser.add_argument("--seed", type=nonnegative_int, default=0)
    parser.add_argument("--drops", type=positive_int, default=128,
                        help="drops per object for stable poses")
    parser.add_argument("--out", required=True)
    parser.add_argument("--no-progress", action="store_true")


def run(args) -> int:
    from corn_drake.assets.library import build_procedural, ingest_folder
    from corn_drake.assets.process import ProcessConfig

    cfg = ProcessConfig()
    cfg.drops.drops = args.drops
    if args.source == "procedural":
        manifest = build_procedural(args.out, args.num, args.seed, cfg, not args.no_progress)
    else:
        manifest = ingest_folder(args.source, args.out, args.seed, cfg, not args.no_progress)
    splits = [o["split"] for o in manifest["objects"]]
    print(f"{splits.count('train')} train + {splits.count('unseen')} unseen objects, "
          f"{len(manifest['rejected'])} rejected; manifest {args.out}/manifest.json")
    for r in manifest["rejected"]:
        print(f"  rejected {r['source']}: {r['reason']}")
    return 0
