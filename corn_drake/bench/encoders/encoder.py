"""`corn-drake bench encoder`: the CORN encoder vs the 3-layer PointNet, latency and peak memory.

Each (encoder, batch) is measured in a fresh subprocess (corn_drake/bench/encoders/encoder_probe.py):
best-of-3 forward latency under inference_mode, in chunks of 256 clouds, and the growth of peak
RSS over the process's size before the forwards. FPS + kNN time is reported for CORN separately
(it is included in its latency).
"""

from __future__ import annotations

import json
import subprocess
import sys

from corn_drake.arguments.value_types import positive_int_list

NAME = "encoder"
HELP = "CORN encoder vs 3-layer PointNet: forward latency and peak memory per batch size"


def add_arguments(parser):
    parser.add_argument("--batches", type=positive_int_list, default="1,64,1024,4096",
                        help="comma-separated batch sizes")


def _probe(kind: str, batch: int) -> dict:
    out = subprocess.run([sys.executable, "-m", "corn_drake.bench.encoders.encoder_probe", kind, str(batch)],
                         check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def run(args) -> dict:
    from corn_drake.nn.encoders.corn_encoder import CORNEncoder
    from corn_drake.nn.encoders.pointnet import PointNetEncoder

    table = []
    for batch in args.batches:
        corn, pn = _probe("corn", batch), _probe("pointnet", batch)
        table.append({"batch": batch, "corn_ms": corn["latency_ms"], "pointnet_ms": pn["latency_ms"],
                      "speedup": pn["latency_ms"] / corn["latency_ms"],
                      "corn_fps_knn_ms": corn["fps_knn_ms"],
                      "corn_peak_mb": corn["peak_mb"], "pointnet_peak_mb": pn["peak_mb"],
                      "memory_ratio": pn["peak_mb"] / max(corn["peak_mb"], 1e-3)})
    by_batch = {row["batch"]: row for row in table}
    result = {"table": table,
              "corn_parameters": sum(p.numel() for p in CORNEncoder().parameters()),
              "pointnet_parameters": sum(p.numel() for p in PointNetEncoder().parameters())}
    for b in (64, 4096):
        if b in by_batch:
            result[f"speedup_b{b}"] = by_batch[b]["speedup"]
    if 4096 in by_batch:
        result["memory_ratio_b4096"] = by_batch[4096]["memory_ratio"]
    return result
