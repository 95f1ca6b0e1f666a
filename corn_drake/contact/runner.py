"""`corn-drake contact-data`: writes the train / val / unseen shards of a contact dataset."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from corn_drake.contact.generate import ContactDataConfig, generate_samples, shard_rng
from corn_drake.contact.gripper_sdf import GripperSDF
from corn_drake.assets.library_clouds import load_object_clouds
from corn_drake.contact.shards import read_shard, shard_is_complete, shard_path, write_manifest, write_shard
from corn_drake.errors import InputError


def split_plan(num_samples: int, eval_samples: int, shard_size: int) -> dict[str, list[int]]:
    """Sample counts per shard for each split."""
    def sizes(total):
        full, rest = divmod(total, shard_size)
        return [shard_size] * full + ([rest] if rest else [])

    return {"train": sizes(num_samples), "val": sizes(eval_samples), "unseen": sizes(eval_samples)}


def effective_eval_samples(num_samples: int, eval_samples: int | None) -> int:
    """Samples in each of val / unseen: `eval_samples`, or by default a tenth of the training
    samples (at least 256)."""
    return eval_samples if eval_samples is not None else max(num_samples // 10, 256)


def generate_dataset(objects_dir: str | Path, out: str | Path, num_samples: int, seed: int,
                     eval_samples: int | None = None, shard_size: int = 4096,
                     progress: bool = True) -> dict:
    from tqdm import tqdm

    out = Path(out)
    objects = load_object_clouds(objects_dir)
    pools = {"train": [o for o in objects if o.split == "train"],
             "unseen": [o for o in objects if o.split == "unseen"]}
    pools["val"] = pools["train"]
    if not pools["train"]:
        raise InputError(f"object library {objects_dir} has no train objects")
    eval_samples = effective_eval_samples(num_samples, eval_samples)
    plan = split_plan(num_samples, eval_samples if pools["unseen"] else 0, shard_size)
    if not pools["unseen"]:
        plan["unseen"] = []
    plan["val"] = split_plan(0, eval_samples, shard_size)["val"]
    sdf, cfg = GripperSDF(), ContactDataConfig()
    total = sum(sum(v) for v in plan.values())
    bar = tqdm(total=total, disable=not progress, desc="contact data", unit="sample")
    t0, generated = time.perf_counter(), 0
    for split, sizes in plan.items():
        for index, size in enumerate(sizes):
            path = shard_path(out, split, index)
            if not shard_is_complete(path, size):  # resume: finished shards are kept
                write_shard(path, generate_samples(pools[split], size, shard_rng(seed, split, index),
                                                   sdf, cfg))
                generated += size
            bar.update(size)
    bar.close()
    stats = {}
    for split, sizes in plan.items():
        labels = [read_shard(shard_path(out, split, i))["labels"] for i in range(len(sizes))]
        if labels:
            lab = np.concatenate(labels)
            stats[split] = {"samples": int(len(lab)), "shards": len(sizes),
                            "positive_sample_fraction": float(lab.any(1).mean()),
                            "positive_point_fraction": float(lab.mean())}
    manifest = {"seed": seed, "objects_dir": str(objects_dir), "points_per_sample": cfg.points,
                "shard_size": shard_size, "splits": stats,
                "objects": {s: [o.id for o in pools[s]] for s in ("train", "unseen")},
                "generated_this_run": generated,
                "seconds_this_run": time.perf_counter() - t0}
    write_manifest(out, manifest)
    return manifest
