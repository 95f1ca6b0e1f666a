"""Pretext pretraining of the CORN patch encoder for the P2V-lite and ROT baselines.

The loop, checkpoints (resumable to the same step with every RNG stream), TensorBoard, metrics.json
and the encoder.pt export are contact pretraining's (pretraining/loop.py); this supplies the data
(pretext/clouds.py: the object library's clouds, drawn on the fly), the models (pretext/p2v.py,
pretext/rot.py) and what "learned" means for a task whose loss has no fixed scale.

Metrics, on a fixed set of eval_samples clouds per split (val: the train objects in other
placements; unseen: the library's unseen objects), drawn once from the run's seed:
- loss: the pretext loss (P2V-lite: SmoothL1 at the masked patches, with fixed masks; ROT: the
  squared Frobenius distance of the rotations);
- reference_loss: the loss of the best input-blind prediction (P2V-lite: every masked patch
  predicted as the mean target over the set; ROT: the one rotation closest to all targets, their
  chordal mean; against uniform relative rotations every constant scores about 6, 126 deg);
- skill = 1 - loss / reference_loss: 0 for a model that ignores its input, 1 for a perfect one.
  This is the record policies check (rl/pretrained_encoders.MIN_PRETEXT_SKILL); a plain loss cannot be,
  since P2V-lite's targets move with its teacher.
- P2V-lite also reports target_std / prediction_std (std over patches, mean over channels;
  point2vec's collapse check: targets near 0 std would make any loss small); ROT the mean
  rotation error in degrees, and the chordal mean's.
The history's step-0 row is the untrained model on the val split.
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import nn

from corn_drake.config.pretraining import PretextConfig
from corn_drake.nn.encoders.corn_encoder import CORNEncoder
from corn_drake.nn.geometry import random_rotations, rotation_angle
from corn_drake.pretext.clouds import SPLITS, LibraryClouds
from corn_drake.pretext.p2v import P2VLiteModel, ema_decay, random_patch_mask
from corn_drake.pretext.rot import (RelativeRotationModel, chordal_mean, frobenius_loss,
                                    relative_rotation)
from corn_drake.pretraining.loop import PretrainLoop

EVAL_CHUNK = 256  # clouds per forward pass in an evaluation


class PretextPretrainer(PretrainLoop):
    evaluate_untrained = True

    def __init__(self, cfg: PretextConfig, library: str | Path, out: str | Path):
        cfg.check()
        self.library = Path(library)
        super().__init__(cfg, out)

    @property
    def is_p2v(self) -> bool:
        return self.cfg.model == "p2v-lite"

    def build_model(self) -> nn.Module:
        encoder = CORNEncoder(dropout=self.cfg.dropout)
        if self.is_p2v:
            return P2VLiteModel(encoder, self.cfg.smooth_l1_beta, self.cfg.target_norm)
        return RelativeRotationModel(encoder)

    def setup(self) -> None:
        self.clouds = LibraryClouds(self.library, point_noise_std=self.cfg.point_noise_std)
        self._eval_sets: dict[str, dict] = {}

    # --- data --------------------------------------------------------------------------------
    def draw(self, split: str, n: int, g: torch.Generator) -> dict[str, torch.Tensor]:
        """n normalised samples of `split` for the model's task."""
        clouds, norm = self.clouds, self.normalization
        surfaces = clouds.objects(split, n, g)
        if self.is_p2v:
            points = clouds.place(surfaces, random_rotations(n, g), g)
            return {"points": norm.points(points), "hand": norm.hand(clouds.hands(n, g)),
                    "mask": random_patch_mask(n, self.model.encoder.num_patches,
                                              self.cfg.mask_ratio, g)}
        R_a, R_b = random_rotations(n, g), random_rotations(n, g)
        return {"points_a": norm.points(clouds.place(surfaces, R_a, g)),
                "hand_a": norm.hand(clouds.hands(n, g)),
                "points_b": norm.points(clouds.place(surfaces, R_b, g)),
                "hand_b": norm.hand(clouds.hands(n, g)),
                "target": relative_rotation(R_a, R_b)}

    def eval_set(self, split: str) -> dict[str, torch.Tensor]:
        """The split's fixed evaluation samples (the same at every evaluation and on resume)."""
        if split not in self._eval_sets:
            g = torch.Generator().manual_seed(1_000_003 * (self.cfg.seed + 1) + SPLITS.index(split))
            self._eval_sets[split] = self.draw(split, self.cfg.eval_samples, g)
        return self._eval_sets[split]

    # --- training ----------------------------------------------------------------------------
    def predict(self, batch: dict) -> tuple[torch.Tensor, torch.Tensor]:
        """(prediction, target) of a batch: masked-patch features, or rotations."""
        if self.is_p2v:
            return self.model(batch["points"], batch["hand"], batch["mask"])
        return (self.model(batch["points_a"], batch["hand_a"], batch["points_b"], batch["hand_b"]),
                batch["target"])

    def pretext_loss(self, prediction, target) -> torch.Tensor:
        if self.is_p2v:
            return self.model.loss_fn(prediction, target)
        return frobenius_loss(prediction, target)

    def loss_on(self, batch: dict) -> torch.Tensor:
        """The pretext loss on a batch of draw()'s samples."""
        return self.pretext_loss(*self.predict(batch))

    def batch_loss(self) -> torch.Tensor:
        return self.loss_on(self.draw("train", self.cfg.batch_size, self.generator))

    def teacher_decay(self, step: int) -> float:
        c = self.cfg
        return ema_decay(step, c.steps, c.ema_start_horizon, c.ema_end_horizon, c.ema_ramp_fraction)

    def after_optimizer_step(self) -> None:
        if self.is_p2v:
            self.model.update_teacher(self.teacher_decay(self.step))

    # --- metrics -----------------------------------------------------------------------------
    @torch.no_grad()
    def evaluate(self, split: str) -> dict:
        if not self.clouds.has(split):
            return {}
        data = self.eval_set(split)
        n = len(next(iter(data.values())))
        self.model.eval()
        parts = [self.predict({k: v[i:i + EVAL_CHUNK] for k, v in data.items()})
                 for i in range(0, n, EVAL_CHUNK)]
        self.model.train()
        prediction = torch.cat([p for p, _ in parts])
        target = torch.cat([t for _, t in parts])
        loss = self.pretext_loss(prediction, target).item()
        if self.is_p2v:
            reference = self.pretext_loss(target.mean(0).expand_as(target), target).item()
            extra = {"target_std": target.std(0).mean().item(),
                     "prediction_std": prediction.std(0).mean().item()}
        else:
            blind = chordal_mean(target).expand_as(target)
            reference = self.pretext_loss(blind, target).item()
            extra = {"rotation_error_deg": rotation_angle(prediction, target).mean().rad2deg().item(),
                     "reference_rotation_error_deg":
                         rotation_angle(blind, target).mean().rad2deg().item()}
        return {"loss": loss, "reference_loss": reference, "skill": 1.0 - loss / reference, **extra}

    def final_metrics(self) -> dict:
        metrics = {"pretext": self.cfg.model, "library": str(self.library),
                   "train_objects": len(self.clouds.ids["train"]),
                   "unseen_objects": len(self.clouds.ids.get("unseen", [])),
                   "loss_kind": "smooth_l1" if self.is_p2v else "frobenius_squared"}
        if self.is_p2v:
            metrics["ema_decay_last"] = self.teacher_decay(max(self.step - 1, 0))
        untrained = next((row for row in self.history if row["step"] == 0), None)
        if untrained is not None:
            metrics["untrained_heldout_pretext_loss"] = untrained.get("val_loss")
            metrics["untrained_heldout_pretext_skill"] = untrained.get("val_skill")
        for split, prefix in (("val", "heldout"), ("unseen", "unseen")):
            for k, v in self.evaluate(split).items():
                metrics[f"{prefix}_pretext_{k}"] = v
        return metrics
