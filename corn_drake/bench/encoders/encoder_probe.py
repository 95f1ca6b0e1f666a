"""One encoder measurement in a fresh process (so peak RSS belongs to this measurement alone).

`python -m corn_drake.bench.encoders.encoder_probe KIND BATCH` prints one JSON line: best-of-3 forward
latency, peak RSS growth during the forwards, and (for corn) the FPS + kNN share.
"""

from __future__ import annotations

import json
import resource
import sys
import time

CHUNK = 256  # clouds per forward on CPU: bounds activations, measured faster than one big batch


def _rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20


def main(kind: str, batch: int) -> dict:
    import torch

    from corn_drake.contract import DEFAULT_NUM_POINTS, HAND_STATE_DIM
    from corn_drake.nn.encoders.corn_encoder import CORNEncoder
    from corn_drake.nn.encoders.patchify import patch_indices
    from corn_drake.nn.encoders.pointnet import PointNetEncoder

    torch.manual_seed(0)
    model = (CORNEncoder() if kind == "corn" else PointNetEncoder(chunk=CHUNK)).eval()
    points = torch.randn(batch, DEFAULT_NUM_POINTS, 3) * 0.3
    hand = torch.randn(batch, HAND_STATE_DIM)

    def forward():
        if kind == "corn":
            return [model(p, h) for p, h in zip(points.split(CHUNK), hand.split(CHUNK))]
        return model(points, hand)

    base = _rss_mb()
    with torch.inference_mode():
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            forward()
            times.append(time.perf_counter() - t0)
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 - base
        result = {"kind": kind, "batch": batch, "latency_ms": 1e3 * min(times), "peak_mb": peak}
        if kind == "corn":
            t0 = time.perf_counter()
            for p in points.split(CHUNK):
                patch_indices(p)
            result["fps_knn_ms"] = 1e3 * (time.perf_counter() - t0)
    return result


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1], int(sys.argv[2]))))
