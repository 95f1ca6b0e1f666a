"""Encoders with their input normalisation, and saving / loading them (encoder.pt).

A network is only meaningful on inputs normalised as it was trained, so policies never see a
bare network: NormalizedEncoder holds the network and its InputNormalization, takes world-frame
clouds and hand states, and is what make_policy_encoder and load_frozen_encoder return.

encoder.pt: {"kind", "state_dict" (the network's), "normalization" (InputNormalization.record()),
"pretraining" (how it was made)}.

The kind names the network and how it was pretrained: "corn" (patch transformer, contact),
"pointnet" (PointNet, contact), "p2v-lite" and "rot" (the same patch transformer as "corn",
pretrained on a pretext task: corn_drake/pretext/). A policy asks for one kind
(policy_kinds.ENCODER_KIND), so an encoder pretrained one way is never used as another.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import torch
from torch import nn

from corn_drake.errors import InputError, MissingInputError
from corn_drake.io_utils import atomic_path
from corn_drake.nn.input_normalization import InputNormalization

ENCODER_KINDS = ("corn", "pointnet", "p2v-lite", "rot")
PATCH_ENCODER_KINDS = ("corn", "p2v-lite", "rot")  # CORNEncoder networks


def make_network(kind: str) -> nn.Module:
    """A freshly initialised network of `kind` (ENCODER_KINDS), without normalisation."""
    from corn_drake.nn.encoder import CORNEncoder
    from corn_drake.nn.pointnet import PointNetEncoder

    if kind in PATCH_ENCODER_KINDS:
        return CORNEncoder()
    if kind == "pointnet":
        return PointNetEncoder()
    raise ValueError(f"unknown encoder kind {kind!r}; expected one of {ENCODER_KINDS}")


class NormalizedEncoder(nn.Module):
    """(world-frame cloud (B, N, 3), hand state (B, 9)) -> the network's output on normalised
    inputs: tokens (B, 1 + G, D) for the patch encoders, a global feature (B, F) for "pointnet"."""

    def __init__(self, kind: str, network: nn.Module, normalization: InputNormalization,
                 pretraining: dict | None = None):
        super().__init__()
        self.kind, self.network, self.normalization = kind, network, normalization
        # How the network was pretrained (steps, held-out / unseen patch metrics): policies
        # check it, so an encoder that never learned its pretraining task is not used unawares. None for a
        # fresh network or an encoder exported before the record existed.
        self.pretraining = pretraining

    def forward(self, cloud: torch.Tensor, hand: torch.Tensor, *args, **kwargs) -> torch.Tensor:
        # Extra arguments (e.g. the CORN encoder's precomputed patch indices) pass through:
        # FPS and kNN are unchanged by a translation and a uniform scale.
        return self.network(self.normalization.points(cloud), self.normalization.hand(hand),
                            *args, **kwargs)


def make_policy_encoder(kind: str) -> NormalizedEncoder:
    """A fresh network of `kind` with the default normalisation (trained end to end by PPO)."""
    return NormalizedEncoder(kind, make_network(kind), InputNormalization())


def save_encoder(path: str | Path, encoder: NormalizedEncoder, pretraining: dict | None = None) -> None:
    """Writes `encoder` (network, normalisation) atomically; `pretraining` records how it was
    made (steps, budget, held-out/unseen patch metrics)."""
    with atomic_path(path) as tmp:
        torch.save({"kind": encoder.kind, "state_dict": encoder.network.state_dict(),
                    "normalization": encoder.normalization.record(),
                    "pretraining": pretraining}, tmp)


def load_frozen_encoder(path: str | Path) -> NormalizedEncoder:
    """The encoder saved at `path` with the normalisation it was pretrained with, in eval mode
    with gradients off."""
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"encoder checkpoint not found: {path}")
    try:
        state = torch.load(path, weights_only=False)
        network = make_network(state["kind"])
        network.load_state_dict(state["state_dict"])
        # encoder.pt files written before the normalisation was saved hold none: every one of
        # them was pretrained with the contract's ENCODER_INPUT_CENTER / ENCODER_INPUT_SCALE,
        # the only values ever used, which InputNormalization() holds.
        record = state.get("normalization")
        normalization = InputNormalization() if record is None else InputNormalization.from_record(record)
    # Garbage bytes fail in the unpickler, a truncated file in torch's zip reader, a checkpoint
    # of something else on its keys, its kind or its normalisation record.
    except (KeyError, TypeError, ValueError, RuntimeError, EOFError, AttributeError,
            pickle.UnpicklingError) as e:
        raise InputError(f"encoder checkpoint {path} is not a saved encoder ({e})") from e
    encoder = NormalizedEncoder(state["kind"], network, normalization, state.get("pretraining"))
    encoder.eval()
    for p in encoder.parameters():
        p.requires_grad_(False)
    return encoder
