"""`corn-drake bench contact-data`: samples/s of the contact-data generator (512 points each).

Objects: the procedural primitives (box, cylinder) with 2048-point clouds, or a library. The
baseline in the same run is the straightforward float64 numpy path (per-box einsum over all
points, then labels in the tool frame) that the batched torch path replaced.
"""

from __future__ import annotations

import time

from corn_drake.arguments.value_types import positive_int

NAME = "contact-data"
HELP = "contact-data generation speed (samples/s) vs the plain numpy path"


def add_arguments(parser):
    parser.add_argument("--objects", default="", help="object library (default: built-in primitives)")
    parser.add_argument("--samples", type=positive_int, default=16384,
                        help="samples generated in the timed run")
    parser.add_argument("--batch", type=positive_int, default=4096,
                        help="samples per generation call")


def _objects(path):
    from corn_drake.assets.library_clouds import ObjectCloud, load_object_clouds
    from corn_drake.scene.objects import box_spec, cylinder_spec

    if path:
        return load_object_clouds(path)
    specs = [box_spec([0.1, 0.06, 0.04], 0.2), box_spec([0.04, 0.04, 0.15], 0.2),
             cylinder_spec(0.03, 0.1, 0.2), cylinder_spec(0.06, 0.03, 0.2)]
    return [ObjectCloud(s.name, "train", s.radius, s.cloud[:, :3]) for s in specs]


def _numpy_baseline(objects, n, rng, sdf):
    """Reference path: float64 numpy, SDF + gradient at every point, labels by tool-frame test."""
    import numpy as np

    from corn_drake.contact.generate import random_rotations

    which = rng.integers(len(objects), size=n)
    local = np.stack([objects[i].points[:2048] for i in which]) * rng.uniform(0.5, 1.5, (n, 1, 1))
    R_h, _ = random_rotations(rng, n)
    R_o, _ = random_rotations(rng, n)
    p_h, p_o = rng.uniform(-0.2, 0.2, (n, 3)), rng.uniform(-0.2, 0.2, (n, 3))
    world = np.einsum("nij,nmj->nmi", R_o, local) + p_o[:, None]
    tool = np.einsum("nji,nmj->nmi", R_h, world - p_h[:, None])
    d, grad = sdf.signed_distance(tool)
    nearest = d.argmin(1)
    u = np.einsum("nij,nj->ni", R_h, grad[np.arange(n), nearest])
    shifted = tool[:, :512] - np.einsum("nji,nj->ni", R_h, d[np.arange(n), nearest, None] * u)[:, None]
    return sdf.inside(shifted)


def run(args) -> dict:
    import numpy as np

    from corn_drake.contact.generate import generate_samples, shard_rng
    from corn_drake.contact.gripper_sdf import GripperSDF

    objects, sdf = _objects(args.objects), GripperSDF()
    generate_samples(objects, 256, shard_rng(0, "train", 99), sdf)  # warm-up
    t0, done, positives = time.perf_counter(), 0, []
    while done < args.samples:
        n = min(args.batch, args.samples - done)
        positives.append(generate_samples(objects, n, shard_rng(0, "train", done), sdf)["labels"].any(1))
        done += n
    fast = args.samples / (time.perf_counter() - t0)
    base_n = min(args.batch, 2048)
    t0 = time.perf_counter()
    _numpy_baseline(objects, base_n, np.random.default_rng(0), sdf)
    base = base_n / (time.perf_counter() - t0)
    return {"samples_per_s": fast, "numpy_baseline_samples_per_s": base, "speedup": fast / base,
            "samples": args.samples, "points_per_sample": 512, "cloud_points": 2048,
            "positive_sample_fraction": float(np.concatenate(positives).mean()),
            "objects": len(objects)}
