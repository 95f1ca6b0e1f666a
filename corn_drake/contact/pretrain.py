"""Contact pretraining of the CORN encoder (and the PointNet baseline) on contact-data shards.

The CORN model predicts, per patch (16 FPS centres x 32 sorted neighbours), whether the gripper
touches it; a patch is positive if any of its points is inside the gripper. The PointNet baseline
predicts per point; its patch predictions are the max over the same patches, so both get the
same patch-level metrics. Run folder: config.yaml, checkpoints/last.pt (atomic, resumable to the
same step with every RNG's state; the one before kept as prev.pt, used if last.pt is unreadable),
tb/, metrics.json, plots/predictions.png, encoder.pt (frozen-encoder export).
"""

from __future__ import annotations

import math
import random
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

from corn_drake.config import PretrainConfig
from corn_drake.contact.shards import load_split
from corn_drake.errors import InputError
from corn_drake.io_utils import atomic_path, load_checkpoint, save_checkpoint, write_json
from corn_drake.nn.encoder import CORNContactModel
from corn_drake.contract import DEFAULT_NUM_POINTS, HAND_STATE_DIM, POSE7_POSITION, POSE7_QUATERNION
from corn_drake.nn.encoder_io import NormalizedEncoder, save_encoder
from corn_drake.nn.geometry import quat_wxyz_to_matrix, rot6d, yaw_matrix
from corn_drake.nn.input_normalization import InputNormalization
from corn_drake.nn.metrics import binary_metrics
from corn_drake.nn.patchify import gather_points, patch_indices
from corn_drake.nn.pointnet import PointNetContactModel


def _global_rng_state() -> dict:
    """Every global RNG a training step may draw from (dropout uses torch's), so a resumed run
    continues the same random stream as an uninterrupted one."""
    state = {"torch": torch.get_rng_state(), "numpy": np.random.get_state(),
             "python": random.getstate()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def _set_global_rng_state(state: dict) -> None:
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    random.setstate(state["python"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


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


class Pretrainer:
    def __init__(self, cfg: PretrainConfig, data: str | Path, out: str | Path):
        if cfg.model not in ("corn", "pointnet"):
            raise ValueError(f"model must be corn or pointnet, got {cfg.model!r}")
        self.cfg, self.out, self.data = cfg, Path(out), Path(data)
        torch.manual_seed(cfg.seed)
        self.model = CORNContactModel() if cfg.model == "corn" else PointNetContactModel()
        # Exported with the encoder: policies normalise their inputs the same way.
        self.normalization = InputNormalization()
        self.optimizer = torch.optim.AdamW(self.model.parameters(), lr=cfg.lr,
                                           weight_decay=cfg.weight_decay)
        self.generator = torch.Generator().manual_seed(cfg.seed)
        self.step, self.history, self.initial_loss = 0, [], None
        self.train_seconds = 0.0  # optimisation wall-clock over all runs (resumes add to it)
        self.train_set = {k: torch.from_numpy(v) for k, v in load_split(self.data, "train").items()
                          if k in ("points", "labels", "hand_pose")}
        self.checkpoint = self.out / "checkpoints" / "last.pt"
        self._load()  # resumes from last.pt (or prev.pt beside it) when there is one

    def lr_at(self, step: int) -> float:
        c = self.cfg
        if step < c.warmup_steps:
            return c.lr * (step + 1) / c.warmup_steps
        t = (step - c.warmup_steps) / max(c.steps - c.warmup_steps, 1)
        return c.min_lr + 0.5 * (c.lr - c.min_lr) * (1 + math.cos(math.pi * min(t, 1.0)))

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

    def _save(self):
        state = {"model": self.model.state_dict(), "optimizer": self.optimizer.state_dict(),
                 "generator": self.generator.get_state(), "rng": _global_rng_state(),
                 "step": self.step, "history": self.history, "model_kind": self.cfg.model,
                 "train_seconds": self.train_seconds}
        save_checkpoint(self.checkpoint, state)

    def _load(self):
        state = load_checkpoint(self.checkpoint, required=("model", "optimizer", "generator",
                                                           "step", "history"))
        if state is None:
            return
        kind = state.get("model_kind", self.cfg.model)
        if kind != self.cfg.model:
            raise InputError(f"{self.checkpoint} holds a {kind!r} model, not {self.cfg.model!r}")
        self.model.load_state_dict(state["model"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.generator.set_state(state["generator"])
        if "rng" in state:  # absent in checkpoints written before it was kept
            _set_global_rng_state(state["rng"])
        self.step, self.history = state["step"], state["history"]
        self.train_seconds = state.get("train_seconds", 0.0)

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

    def train(self, progress: bool = True) -> dict:
        from torch.utils.tensorboard import SummaryWriter
        from tqdm import tqdm

        cfg = self.cfg
        writer = SummaryWriter(str(self.out / "tb"))
        n = len(self.train_set["points"])
        bar = tqdm(total=cfg.steps, initial=self.step, disable=not progress, desc=f"pretrain {cfg.model}")
        t0 = time.perf_counter()
        while self.step < cfg.steps:
            t_step = time.perf_counter()
            idx = torch.randint(n, (cfg.batch_size,), generator=self.generator)
            pts, hand = prepare(self.train_set["points"][idx], self.train_set["hand_pose"][idx], cfg,
                                self.generator, self.normalization)
            _, _, loss = self._forward(pts, hand, self.train_set["labels"][idx])
            if self.initial_loss is None:
                self.initial_loss = loss.item()
            for group in self.optimizer.param_groups:
                group["lr"] = self.lr_at(self.step)
            self.optimizer.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(self.model.parameters(), cfg.max_grad_norm)
            self.optimizer.step()
            self.step += 1
            self.train_seconds += time.perf_counter() - t_step
            writer.add_scalar("train/loss", loss.item(), self.step)
            writer.add_scalar("train/lr", self.lr_at(self.step - 1), self.step)
            bar.update(1)
            bar.set_postfix(loss=f"{loss.item():.3f}")
            if self.step % cfg.eval_every == 0 or self.step == cfg.steps:
                row = {"step": self.step, "loss": loss.item(),
                       **{f"val_{k}": v for k, v in self.evaluate("val").items()}}
                self.history.append(row)
                for k, v in row.items():
                    if k.startswith("val_"):
                        writer.add_scalar(f"val/{k[4:]}", v, self.step)
            if self.step % cfg.checkpoint_every == 0:
                self._save()
        bar.close()
        self._save()
        writer.close()
        metrics = {"model": cfg.model, "steps": self.step, "batch_size": cfg.batch_size,
                   "samples_seen": self.step * cfg.batch_size, "train_samples": n,
                   "seconds_this_run": time.perf_counter() - t0,
                   "train_seconds": self.train_seconds, "lr": cfg.lr,
                   "parameters": sum(p.numel() for p in self.model.parameters())}
        for split, prefix in (("val", "heldout"), ("unseen", "unseen")):
            for k, v in self.evaluate(split).items():
                metrics[f"{prefix}_patch_{k}"] = v
        write_json(self.out / "metrics.json", metrics)
        save_encoder(self.out / "encoder.pt",
                     NormalizedEncoder(cfg.model, self.model.encoder, self.normalization),
                     pretraining=metrics)
        plot_predictions(self, self.out / "plots" / "predictions.png")
        return metrics


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
