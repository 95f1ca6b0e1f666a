"""Contact pretraining of the CORN encoder (and the PointNet baseline) on contact-data shards.

The CORN model predicts, per patch (16 FPS centres x 32 sorted neighbours), whether the gripper
touches it; a patch is positive if any of its points is inside the gripper. The PointNet baseline
predicts per point; its patch predictions are the max over the same patches, so both get the
same patch-level metrics. The loop, checkpoints (resumable to the same step) and the run folder
are pretraining/loop.py's, shared with the pretext baselines (pretext/); this adds
plots/predictions.png.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

from corn_drake.config.plumbing.bounds import check_bounds
from corn_drake.config.pretraining import PretrainConfig
from corn_drake.contact.shards import load_split
from corn_drake.storage.atomic_files import atomic_path
from corn_drake.nn.encoders.corn_encoder import CORNContactModel
from corn_drake.contract import DEFAULT_NUM_POINTS, HAND_STATE_DIM, POSE7_POSITION, POSE7_QUATERNION
from corn_drake.nn.geometry import quat_wxyz_to_matrix, rot6d, yaw_matrix
from corn_drake.nn.encoders.input_normalization import InputNormalization
from corn_drake.nn.encoders.metrics import binary_metrics
from corn_drake.nn.encoders.patchify import gather_points, patch_indices
from corn_drake.nn.encoders.pointnet import PointNetContactModel
from corn_drake.pretraining.loop import PretrainLoop


def hand9(hand_pose: torch.Tensor, normalization: InputNormalization) -> torch.Tensor:
    """Tool pose (B, 7: xyz + wxyz) -> normalised position + 6D rotation (B, 9)."""
    p, q = hand_pose[:, POSE7_POSITION], hand_pose[:, POSE7_QUATERNION]
    return normalization.hand(torch.cat([p, rot6d(quat_wxyz_to_matrix(q))], -1))


def augment(points, hand_pose, cfg: PretrainConfig, g: torch.Generator,
            normalization: InputNormalization):
    """Random yaw about the cloud centroid and a translation, applied to cloud and gripper alike,
    then point noise on the cloud; returns the normalised (points, 9-D hand)."""
    B = points.shape[0]
    center = points.mean(1, keepdim=True)
    R = yaw_matrix(torch.rand(B, generator=g) * 2 * math.pi)
    shift = torch.randn(B, 1, 3, generator=g) * cfg.translate_std
    points = (points - center) @ R.transpose(1, 2) + center + shift
    hand_R = R @ quat_wxyz_to_matrix(hand_pose[:, POSE7_QUATERNION])
    hand_p = ((hand_pose[:, None, POSE7_POSITION] - center) @ R.transpose(1, 2) + center + shift)[:, 0]
    points = points + torch.randn(points.shape, generator=g) * cfg.point_noise_std
    return normalization.points(points), normalization.hand(torch.cat([hand_p, rot6d(hand_R)], -1))


def prepare(points, hand_pose, cfg, g=None, normalization: InputNormalization | None = None):
    """Normalised (points, 9-D hand) for the encoder; augmented when a generator is given.
    `normalization`: what the encoder is pretrained with (default: the contract's values)."""
    normalization = normalization or InputNormalization()
    points, hand_pose = points.float(), hand_pose.float()
    if g is not None:
        return augment(points, hand_pose, cfg, g, normalization)
    return normalization.points(points), hand9(hand_pose, normalization)


def patch_labels(labels: torch.Tensor, knn_idx: torch.Tensor) -> torch.Tensor:
    """(B, G): a patch is in contact if any of its points is."""
    return gather_points(labels.unsqueeze(-1).float(), knn_idx)[..., 0].amax(-1) > 0.5


class Pretrainer(PretrainLoop):
    """Contact pretraining on the shards of a contact-data folder (the loop: pretraining/loop.py)."""

    def __init__(self, cfg: PretrainConfig, data: str | Path, out: str | Path):
        if cfg.model not in ("corn", "pointnet"):
            raise ValueError(f"model must be corn or pointnet, got {cfg.model!r}")
        check_bounds(cfg)  # a config made in code gets the same range checks as a loaded one
        self.data = Path(data)
        super().__init__(cfg, out)

    def build_model(self) -> nn.Module:
        return CORNContactModel() if self.cfg.model == "corn" else PointNetContactModel()

    @property
    def contact_head(self) -> nn.Module:
        return self.model.head

    def setup(self) -> None:
        self.train_set = {k: torch.from_numpy(v) for k, v in load_split(self.data, "train").items()
                          if k in ("points", "labels", "hand_pose")}

    def _forward(self, points, hand, labels):
        """(patch logits, patch labels, loss)."""
        if self.cfg.model == "corn":
            logits, (_, knn) = self.model(points, hand)
            targets = patch_labels(labels, knn)
            return logits, targets, nn.functional.binary_cross_entropy_with_logits(logits, targets.float())
        point_logits = self.model(points, hand)
        loss = nn.functional.binary_cross_entropy_with_logits(point_logits, labels.float())
        _, knn = patch_indices(points)
        logits = gather_points(point_logits.unsqueeze(-1), knn)[..., 0].amax(-1)
        return logits, patch_labels(labels, knn), loss

    def batch_loss(self) -> torch.Tensor:
        cfg = self.cfg
        idx = torch.randint(len(self.train_set["points"]), (cfg.batch_size,), generator=self.generator)
        pts, hand = prepare(self.train_set["points"][idx], self.train_set["hand_pose"][idx], cfg,
                            self.generator, self.normalization)
        return self._forward(pts, hand, self.train_set["labels"][idx])[2]

    @torch.no_grad()
    def evaluate(self, split: str) -> dict:
        try:
            data = load_split(self.data, split)
        except ValueError:
            return {}
        n = min(self.cfg.eval_samples, len(data["points"]))
        self.model.eval()
        logits, targets = [], []
        for i in range(0, n, 512):
            sl = slice(i, min(i + 512, n))
            pts, hand = prepare(torch.from_numpy(data["points"][sl]), torch.from_numpy(data["hand_pose"][sl]),
                                self.cfg, normalization=self.normalization)
            lg, tg, _ = self._forward(pts, hand, torch.from_numpy(data["labels"][sl]))
            logits.append(lg)
            targets.append(tg)
        self.model.train()
        return binary_metrics(torch.cat(logits), torch.cat(targets))

    def final_metrics(self) -> dict:
        metrics = {"train_samples": len(self.train_set["points"])}
        for split, prefix in (("val", "heldout"), ("unseen", "unseen")):
            for k, v in self.evaluate(split).items():
                metrics[f"{prefix}_patch_{k}"] = v
        return metrics

    def write_plots(self) -> None:
        plot_predictions(self, self.out / "plots" / "predictions.png")


def seconds_per_step(model_kind: str, batch_size: int, repeats: int = 3) -> float:
    """Wall-clock of one optimisation step of `model_kind` at `batch_size` (after a warm-up
    step), on random clouds: what an equal-time budget converts into steps."""
    torch.manual_seed(0)
    model = CORNContactModel() if model_kind == "corn" else PointNetContactModel()
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4)
    points = torch.randn(batch_size, DEFAULT_NUM_POINTS, 3) * 0.2
    hand = torch.randn(batch_size, HAND_STATE_DIM)
    times = []
    for _ in range(repeats + 1):
        t = time.perf_counter()
        out = model(points, hand)
        logits = out[0] if isinstance(out, tuple) else out
        optimizer.zero_grad()
        logits.float().square().mean().backward()
        optimizer.step()
        times.append(time.perf_counter() - t)
    return float(np.median(times[1:]))


def plot_predictions(trainer: Pretrainer, path: Path, count: int = 3) -> None:
    """A few unseen (or held-out) clouds coloured by predicted vs true patch contact."""
    # A Figure of its own, not pyplot: writing the file leaves the process's backend alone,
    # so a notebook that trains in its kernel keeps plotting inline.
    from matplotlib.figure import Figure

    from corn_drake.scene.gripper import gripper_boxes

    try:
        data = load_split(trainer.data, "unseen")
    except ValueError:
        data = load_split(trainer.data, "val")
    labels = data["labels"]
    picks = np.flatnonzero(labels.any(1))[:count]
    fig = Figure(figsize=(4 * len(picks), 8))
    trainer.model.eval()
    with torch.no_grad():
        for col, i in enumerate(picks):
            pts_w = torch.from_numpy(data["points"][i:i + 1])
            pts, hand = prepare(pts_w, torch.from_numpy(data["hand_pose"][i:i + 1]), trainer.cfg,
                                normalization=trainer.normalization)
            logits, targets, _ = trainer._forward(pts, hand, torch.from_numpy(labels[i:i + 1]))
            _, knn = patch_indices(pts)
            point_patch = torch.zeros(pts.shape[1], dtype=torch.long)
            point_patch[knn[0].flatten()] = torch.arange(16).repeat_interleave(32)
            for row, (values, title) in enumerate(((logits[0] > 0, "predicted"), (targets[0], "true"))):
                ax = fig.add_subplot(2, len(picks), row * len(picks) + col + 1, projection="3d")
                colors = np.where(values[point_patch].numpy(), "tab:red", "tab:blue")
                p = data["points"][i]
                ax.scatter(p[:, 0], p[:, 1], p[:, 2], c=colors, s=3)
                R = quat_wxyz_to_matrix(torch.from_numpy(data["hand_pose"][i, 3:])).numpy()
                for box in gripper_boxes():
                    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
                    c = (box.X_TB[:3, :3] @ (corners * box.half_extents).T).T + box.X_TB[:3, 3]
                    c = c @ R.T + data["hand_pose"][i, :3]
                    for a in range(8):
                        for b in range(a + 1, 8):
                            if bin(a ^ b).count("1") == 1:
                                ax.plot(*zip(c[a], c[b]), color="k", lw=0.6)
                ax.set_title(f"sample {i}: {title} contact patches")
    trainer.model.train()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=80)
