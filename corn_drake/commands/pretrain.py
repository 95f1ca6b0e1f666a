"""`corn-drake pretrain`: contact pretraining of the CORN encoder and/or the PointNet baseline.

With --model both, CORN and PointNet are trained on the same data for the same steps and batch,
in OUT/corn and OUT/pointnet; OUT/metrics.json holds CORN's metrics with PointNet's under
"pointnet", and OUT/encoder.pt is the frozen CORN encoder for `corn-drake train --policy corn`.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

NAME = "pretrain"
HELP = "pretrain the patch encoder on gripper contact (resumes from OUT/.../checkpoints/last.pt)"


def add_arguments(parser):
    parser.add_argument("--data", required=True, help="contact-data folder")
    parser.add_argument("--out", required=True, help="run folder, e.g. runs/pretrain")
    parser.add_argument("--model", choices=("corn", "pointnet", "both"), default="both")
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--pointnet-steps", type=int, default=None,
                        help="PointNet steps (default: the same as --steps)")
    parser.add_argument("--batch-size", type=int, default=1024)
    parser.add_argument("--eval-every", type=int, default=250)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-progress", action="store_true")


def run(args) -> int:
    from corn_drake.config import PretrainConfig
    from corn_drake.contact.pretrain import Pretrainer
    from corn_drake.io_utils import write_json, write_text
    from pydrake.common.yaml import yaml_dump_typed

    out = Path(args.out)
    models = ["corn", "pointnet"] if args.model == "both" else [args.model]
    results = {}
    for model in models:
        steps = args.pointnet_steps if model == "pointnet" and args.pointnet_steps else args.steps
        cfg = PretrainConfig(model=model, steps=steps, batch_size=args.batch_size,
                             warmup_steps=min(100, max(steps // 10, 1)), eval_every=args.eval_every,
                             checkpoint_every=args.eval_every, seed=args.seed)
        run_dir = out / model
        run_dir.mkdir(parents=True, exist_ok=True)
        write_text(run_dir / "config.yaml", yaml_dump_typed(cfg))
        results[model] = Pretrainer(cfg, args.data, run_dir).train(progress=not args.no_progress)
        print(f"{model}: unseen patch accuracy {results[model].get('unseen_patch_accuracy', float('nan')):.3f}, "
              f"F1 {results[model].get('unseen_patch_f1', float('nan')):.3f}")
    merged_path = out / "metrics.json"
    merged = json.loads(merged_path.read_text()) if merged_path.exists() else {}
    if "corn" in results:
        merged.update(results["corn"])
        shutil.copyfile(out / "corn" / "encoder.pt", out / "encoder.pt")
    if "pointnet" in results:
        merged["pointnet"] = results["pointnet"]
    write_json(merged_path, merged)
    print(f"wrote {merged_path}")
    return 0
