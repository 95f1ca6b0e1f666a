"""Saving and loading pretrained encoders (frozen export the policies load)."""

from __future__ import annotations

import pickle
from pathlib import Path

import torch
from torch import nn

from corn_drake.errors import InputError, MissingInputError
from corn_drake.io_utils import atomic_path


def make_encoder(kind: str) -> nn.Module:
    """A freshly initialised encoder of `kind` ("corn" or "pointnet")."""
    from corn_drake.nn.encoder import CORNEncoder
    from corn_drake.nn.pointnet import PointNetEncoder

    if kind == "corn":
        return CORNEncoder()
    if kind == "pointnet":
        return PointNetEncoder()
    raise ValueError(f"unknown encoder kind {kind!r}")


def save_encoder(path: str | Path, kind: str, encoder: nn.Module,
                 pretraining: dict | None = None) -> None:
    """`pretraining` records how the encoder was made (steps, budget, held-out/unseen patch
    metrics): policies check it, so an encoder that never learned contact is not used unawares."""
    with atomic_path(path) as tmp:
        torch.save({"kind": kind, "state_dict": encoder.state_dict(),
                    "pretraining": pretraining}, tmp)


def load_frozen_encoder(path: str | Path) -> nn.Module:
    """The encoder saved at `path`, in eval mode with gradients off."""
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"encoder checkpoint not found: {path}")
    try:
        state = torch.load(path, weights_only=False)
        encoder = make_encoder(state["kind"])
        encoder.load_state_dict(state["state_dict"])
    # Garbage bytes fail in the unpickler, a truncated file in torch's zip reader, a checkpoint
    # of something else on its keys or its kind.
    except (KeyError, TypeError, ValueError, RuntimeError, EOFError, pickle.UnpicklingError) as e:
        raise InputError(f"encoder checkpoint {path} is not a saved encoder ({e})") from e
    # None for encoders exported before the record existed.
    encoder.pretraining = state.get("pretraining")
    encoder.eval()
    for p in encoder.parameters():
        p.requires_grad_(False)
    return encoder
