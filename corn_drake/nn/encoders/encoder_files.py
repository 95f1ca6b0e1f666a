"""Encoders with their input normalisation, and saving / loading them (encoder.pt).

A network is only meaningful on inputs normalised as it was trained, so policies never see a
bare network: NormalizedEncoder holds the network and its InputNormalization, takes world-frame
clouds and hand states, and is what make_policy_encoder and load_frozen_encoder return.

encoder.pt: {"kind", "state_dict" (the network's), "normalization" (InputNormalization.record()),
"pretraining" (how it was made), and for the contact-pretrained kinds "contact_head" (the
prediction head's state_dict: policies never read it; load_contact_model does, so the encoder's
contact predictions can be shown from the file alone)}.

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

from corn_drake.errors import InputError, MissingInputError, load_error_detail, network_mismatch
from corn_drake.storage.atomic_files import atomic_path
from corn_drake.storage.checkpoint_files import save_torch
from corn_drake.nn.encoders.input_normalization import InputNormalization

ENCODER_KINDS = ("corn", "pointnet", "p2v-lite", "rot")
PATCH_ENCODER_KINDS = ("corn", "p2v-lite", "rot")  # CORNEncoder networks


def make_network(kind: str) -> nn.Module:
    """A freshly initialised network of `kind` (ENCODER_KINDS), without normalisation."""
    from corn_drake.nn.encoders.corn_encoder import CORNEncoder
    from corn_drake.nn.encoders.pointnet import PointNetEncoder

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


def save_encoder(path: str | Path, encoder: NormalizedEncoder, pretraining: dict | None = None,
                 contact_head: nn.Module | None = None) -> None:
    """Writes `encoder` (network, normalisation) atomically; `pretraining` records how it was
    made (steps, budget, held-out/unseen patch metrics); `contact_head`: the contact model's
    head, kept beside the encoder (contact-pretrained kinds)."""
    state = {"kind": encoder.kind, "state_dict": encoder.network.state_dict(),
             "normalization": encoder.normalization.record(), "pretraining": pretraining}
    if contact_head is not None:
        state["contact_head"] = contact_head.state_dict()
    with atomic_path(path) as tmp:
        save_torch(tmp, state)  # a full disk raises OSError(ENOSPC), not torch's RuntimeError


def load_contact_model(path: str | Path) -> tuple[nn.Module, InputNormalization]:
    """The contact model (encoder + head, eval mode) saved in the encoder file `path`, with the
    input normalisation it was pretrained with: CORNContactModel for "corn" (patch logits),
    PointNetContactModel for "pointnet" (point logits). An encoder file without a head (a
    pretext kind, or one exported before heads were kept) is an InputError naming it."""
    from corn_drake.nn.encoders.corn_encoder import CORNContactModel
    from corn_drake.nn.encoders.pointnet import PointNetContactModel

    encoder, state = _read_encoder_file(path)
    if "contact_head" not in state:
        raise InputError(f"encoder file {path} holds no contact head ({encoder.kind} encoder"
                         + ("; re-export it with `corn-drake pretrain` on its run folder)"
                            if encoder.kind in ("corn", "pointnet") else ", not contact-pretrained)"))
    model = (CORNContactModel if encoder.kind == "corn" else PointNetContactModel)(encoder.network)
    try:
        model.head.load_state_dict(state["contact_head"])
    except RuntimeError as e:
        raise InputError(f"encoder file {path}: its contact head does not fit this version "
                         f"({load_error_detail(e)})") from None
    return model.eval(), encoder.normalization


def load_frozen_encoder(path: str | Path) -> NormalizedEncoder:
    """The encoder saved at `path` with the normalisation it was pretrained with, in eval mode
    with gradients off."""
    return _read_encoder_file(path)[0]


def _read_encoder_file(path: str | Path) -> tuple[NormalizedEncoder, dict]:
    """(the frozen encoder, the file's whole saved dict) of the encoder file `path`."""
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"encoder checkpoint not found: {path}")
    try:
        state = torch.load(path, weights_only=False)
        network = make_network(state["kind"])
        try:
            network.load_state_dict(state["state_dict"])
        except RuntimeError as e:  # a network changed since (e.g. the PointNet's input channels)
            raise network_mismatch(path, state["kind"], e) from None
        # encoder.pt files written before the normalisation was saved hold none: every one of
        # them was pretrained with the contract's ENCODER_INPUT_CENTER / ENCODER_INPUT_SCALE,
        # the only values ever used, which InputNormalization() holds.
        record = state.get("normalization")
        normalization = InputNormalization() if record is None else InputNormalization.from_record(record)
    # Garbage bytes fail in the unpickler, a truncated file in torch's zip reader, a checkpoint
    # of something else on its keys, its kind or its normalisation record.
    except InputError:
        raise
    except (KeyError, TypeError, ValueError, RuntimeError, EOFError, AttributeError,
            pickle.UnpicklingError) as e:
        raise InputError(f"encoder checkpoint {path} is not a saved encoder ({e})") from e
    encoder = NormalizedEncoder(state["kind"], network, normalization, state.get("pretraining"))
    encoder.eval()
    for p in encoder.parameters():
        p.requires_grad_(False)
    return encoder, state
