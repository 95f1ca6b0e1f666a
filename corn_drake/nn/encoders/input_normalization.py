"""The encoders' input normalisation, (x - center) / scale on points and on the hand position.

An encoder only works on inputs normalised as it was pretrained, so the normalisation travels
with it: encoder.pt records it (nn/encoders/encoder_files.py), and as a module with buffers it is part of
every policy checkpoint that holds the encoder. The default values are the contract's
ENCODER_INPUT_CENTER / ENCODER_INPUT_SCALE.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from corn_drake.contract import ENCODER_INPUT_CENTER, ENCODER_INPUT_SCALE, POSE9_POSITION


class InputNormalization(nn.Module):
    def __init__(self, center=ENCODER_INPUT_CENTER, scale: float = ENCODER_INPUT_SCALE):
        super().__init__()
        center = [float(c) for c in center]
        if len(center) != 3 or not all(math.isfinite(c) for c in center):
            raise ValueError(f"normalisation center must be 3 finite numbers, got {center}")
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"normalisation scale must be a finite number > 0, got {scale}")
        self.register_buffer("center", torch.tensor(center, dtype=torch.float32))
        self.register_buffer("scale", torch.tensor(float(scale), dtype=torch.float32))

    def points(self, x: torch.Tensor) -> torch.Tensor:
        """Points (..., 3), world frame -> normalised."""
        return (x - self.center.to(x.dtype)) / self.scale.to(x.dtype)

    def hand(self, hand: torch.Tensor) -> torch.Tensor:
        """Hand state (..., 9): position normalised, 6D rotation unchanged."""
        return torch.cat([self.points(hand[..., POSE9_POSITION]),
                          hand[..., POSE9_POSITION.stop:]], dim=-1)

    def record(self) -> dict:
        """Plain values for encoder.pt (readable without this class)."""
        return {"center": self.center.tolist(), "scale": float(self.scale)}

    @classmethod
    def from_record(cls, record: dict) -> "InputNormalization":
        """Back from record(); a malformed record raises ValueError naming what is wrong."""
        if not isinstance(record, dict) or set(record) != {"center", "scale"}:
            raise ValueError(f"normalisation record must hold 'center' and 'scale', got {record!r}")
        return cls(record["center"], float(record["scale"]))

    def extra_repr(self) -> str:
        return f"center={self.center.tolist()}, scale={float(self.scale)}"
