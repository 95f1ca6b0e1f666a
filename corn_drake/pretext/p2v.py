"""P2V-lite: the CORN patch encoder pretrained with point2vec's self-distillation (pure torch).

Recipe (point2vec, after data2vec), with the paper's two changes for a 2-layer encoder:
- A teacher, an exponential moving average of the student's transformer layers and final
  LayerNorm, encodes the whole cloud. The patch tokeniser, position embedding and hand token are
  shared (copied every step), as point2vec and data2vec share their input embeddings.
- The student sees the same cloud with a random mask_ratio of its patches (10 of 16) replaced by
  a learned mask token; a masked patch keeps its position embedding (where it is, not what it
  holds). The hand token is never masked.
- Targets: the teacher's patch features after the final layer's LayerNorm only (point2vec
  averages its last 6 of 12 layers; the paper keeps the same 50 % with 1 of 2 layers, i.e. the
  final one), normalised again by a parameter-free layer norm (point2vec's target norm).
- A regressor Linear-GELU-Linear (128) on the student's output at the masked patches predicts
  the targets; SmoothL1 (beta 2) over the masked patches, as the authors' code.
- Dropout in place of DropPath (PretextConfig.dropout).

Where the student puts its mask tokens: in the encoder itself (data2vec; point2vec's
no-decoder variant), not in a separate decoder after an encoder that sees only the visible
patches (point2vec's default, 4 decoder layers behind 12 encoder layers): a decoder twice as
deep as this encoder would do the work the encoder is meant to learn, and policies use the
encoder on whole clouds.

EMA schedule: PretextConfig.ema_* (point2vec's 0.9998 -> 0.99999 over the first quarter, kept as
fractions of the run's length).
"""

from __future__ import annotations

import copy

import torch
from torch import nn

from corn_drake.nn.encoders.corn_encoder import CORNEncoder
from corn_drake.nn.encoders.patchify import patch_indices

# Parts of the encoder the teacher shares with the student (input embeddings); the rest (the
# transformer layers and the final norm) is the moving average.
SHARED = ("tokenizer", "position", "hand")
TARGET_NORMS = ("instance", "layer")


def ema_decay(step: int, total_steps: int, start_horizon: float, end_horizon: float,
              ramp_fraction: float) -> float:
    """The teacher's decay after optimiser step `step` (0-based) of a `total_steps` run: linear
    from 1 - 1/(start_horizon * total) to 1 - 1/(end_horizon * total) over the first
    ramp_fraction of the run, then constant; a horizon below one step is one step (decay 0)."""
    def decay(horizon_fraction):
        return 1.0 - 1.0 / max(horizon_fraction * total_steps, 1.0)

    start, end = decay(start_horizon), decay(end_horizon)
    t = min(step / max(ramp_fraction * total_steps, 1.0), 1.0)
    return start + (end - start) * t


def normalize_targets(features: torch.Tensor, kind: str) -> torch.Tensor:
    """Parameter-free normalisation of the teacher's patch features (B, G, D): "layer" over
    each patch's channels, "instance" over each channel's patches of one cloud."""
    if kind == "layer":
        return nn.functional.layer_norm(features, features.shape[-1:])
    return nn.functional.instance_norm(features.transpose(1, 2)).transpose(1, 2)


def random_patch_mask(batch: int, patches: int, ratio: float, g: torch.Generator) -> torch.Tensor:
    """(batch, patches) bool: round(ratio * patches) patches per cloud (at least 1), chosen
    uniformly."""
    k = max(1, round(ratio * patches))
    order = torch.rand(batch, patches, generator=g).argsort(dim=1)
    mask = torch.zeros(batch, patches, dtype=torch.bool)
    mask.scatter_(1, order[:, :k], True)
    return mask


class P2VLiteModel(nn.Module):
    def __init__(self, encoder: CORNEncoder | None = None, smooth_l1_beta: float = 2.0,
                 target_norm: str = "instance"):
        super().__init__()
        if target_norm not in TARGET_NORMS:
            raise ValueError(f"target_norm must be one of {TARGET_NORMS}, got {target_norm!r}")
        self.target_norm = target_norm
        self.encoder = encoder or CORNEncoder(dropout=0.1)
        dim = self.encoder.dim
        # point2vec's mask-token initialisation: truncated normal, std 0.02.
        self.mask_token = nn.Parameter(nn.init.trunc_normal_(torch.zeros(dim), std=0.02,
                                                             a=-0.02, b=0.02))
        self.regressor = nn.Sequential(nn.Linear(dim, dim), nn.GELU(), nn.Linear(dim, dim))
        self.teacher = copy.deepcopy(self.encoder).requires_grad_(False).eval()
        self.loss_fn = nn.SmoothL1Loss(beta=smooth_l1_beta)

    def train(self, mode: bool = True):
        super().train(mode)
        self.teacher.eval()  # targets never see dropout
        return self

    @torch.no_grad()
    def update_teacher(self, decay: float) -> None:
        """teacher <- decay * teacher + (1 - decay) * student on the layers and final norm;
        the shared input embeddings are copied."""
        student = dict(self.encoder.named_parameters())
        for name, p in self.teacher.named_parameters():
            if name.split(".")[0] in SHARED:
                p.copy_(student[name])
            else:
                p.lerp_(student[name], 1.0 - decay)

    def forward(self, points: torch.Tensor, hand: torch.Tensor, mask: torch.Tensor):
        """Normalised clouds (B, N, 3), hands (B, 9), patch mask (B, G) -> (predictions (M, D),
        targets (M, D)) at the M masked patches."""
        encoder = self.encoder
        indices = patch_indices(points, encoder.num_patches, encoder.patch_size)
        tokens, centers = encoder.tokenize(points, indices)
        positions = encoder.embed_positions(centers)
        with torch.no_grad():
            full = self.teacher.transform(hand, tokens + positions)[:, 1:]
            targets = normalize_targets(full, self.target_norm)[mask]
        corrupted = torch.where(mask.unsqueeze(-1), self.mask_token.to(tokens.dtype), tokens)
        student = encoder.transform(hand, corrupted + positions)[:, 1:]
        return self.regressor(student[mask]), targets

    def loss(self, points, hand, mask) -> torch.Tensor:
        return self.loss_fn(*self(points, hand, mask))
