"""Actor and twin critic heads for a contact-primitive policy (HACMan-style, per location).

The policy chooses WHERE to touch an object (one of L candidate locations, e.g. the patch
centres of the point-cloud transformer) and a push motion for that location. Both heads run the
same small MLP on every location independently, so they see, per location, the concatenation of
its token, its local extras and the state's global context (broadcast to every location):

    features = {"tokens": (B, L, D), "local": (B, L, K), "global": (B, G)}

The actor proposes a motion for every location at once (B, L, motion_dim); the critic scores
every (location, motion) pair at once (B, L). Scoring all locations in one pass is what lets the
learner both pick the location (argmax / softmax over the scores) and train the actor on every
location, as HACMan does.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch
from torch import nn

Features = Mapping[str, torch.Tensor]

FEATURE_KEYS = ("tokens", "local", "global")


def location_features_dims(features: Features) -> tuple[int, int, int]:
    """(D, K, G) of a features dict: token, per-location-extra and global widths.

    Checks the ranks and that batch and location counts agree, so callers learn of a malformed
    dict here rather than from a cryptic concat error deep inside a head.
    """
    if not isinstance(features, Mapping):
        raise ValueError(f"features: expected a dict of tensors, got {type(features).__name__}")
    for key in FEATURE_KEYS:
        if key not in features:
            raise ValueError(f"features: missing key {key!r}")
    tokens, local, glob = (features[k] for k in FEATURE_KEYS)
    if tokens.dim() != 3:
        raise ValueError(f"features['tokens']: expected (B, L, D), got shape {tuple(tokens.shape)}")
    if local.dim() != 3:
        raise ValueError(f"features['local']: expected (B, L, K), got shape {tuple(local.shape)}")
    if glob.dim() != 2:
        raise ValueError(f"features['global']: expected (B, G), got shape {tuple(glob.shape)}")
    if local.shape[:2] != tokens.shape[:2]:
        raise ValueError(f"features['local']: batch/location dims {tuple(local.shape[:2])} differ "
                         f"from tokens' {tuple(tokens.shape[:2])}")
    if glob.shape[0] != tokens.shape[0]:
        raise ValueError(f"features['global']: batch size {glob.shape[0]} differs from tokens' "
                         f"{tokens.shape[0]}")
    return int(tokens.shape[2]), int(local.shape[2]), int(glob.shape[1])


def _per_location_input(features: Features, dims: tuple[int, int, int]) -> torch.Tensor:
    """(B, L, D + K + G): every location's token and extras with the global context appended."""
    found = location_features_dims(features)
    for name, want, got in zip(FEATURE_KEYS, dims, found):
        if want != got:
            raise ValueError(f"features[{name!r}]: last dim {got}, the head was built for {want}")
    tokens, local, glob = (features[k] for k in FEATURE_KEYS)
    batch, locations = tokens.shape[:2]
    broadcast = glob.unsqueeze(1).expand(batch, locations, glob.shape[1])
    return torch.cat([tokens, local, broadcast], dim=-1)


def _mlp(in_dim: int, hidden: int, out_dim: int) -> nn.Sequential:
    # LayerNorm keeps the inputs' very different scales (tokens vs. raw poses) from dominating.
    return nn.Sequential(
        nn.Linear(in_dim, hidden), nn.LayerNorm(hidden), nn.ReLU(),
        nn.Linear(hidden, hidden), nn.LayerNorm(hidden), nn.ReLU(),
        nn.Linear(hidden, out_dim),
    )


def _check_dims(token_dim: int, local_dim: int, global_dim: int, hidden: int,
                motion_dim: int) -> None:
    for name, value, least in (("token_dim", token_dim, 1), ("local_dim", local_dim, 0),
                               ("global_dim", global_dim, 0), ("hidden", hidden, 1),
                               ("motion_dim", motion_dim, 1)):
        if not isinstance(value, int) or value < least:
            raise ValueError(f"{name}: expected an int >= {least}, got {value!r}")


class PrimitiveActor(nn.Module):
    """Proposes a push motion in [-1, 1]^motion_dim for every candidate location."""

    def __init__(self, token_dim: int, local_dim: int, global_dim: int, hidden: int = 256,
                 motion_dim: int = 3):
        super().__init__()
        _check_dims(token_dim, local_dim, global_dim, hidden, motion_dim)
        self.dims = (token_dim, local_dim, global_dim)
        self.motion_dim = motion_dim
        self.net = _mlp(token_dim + local_dim + global_dim, hidden, motion_dim)

    def forward(self, features: Features) -> torch.Tensor:
        """(B, L, motion_dim) motions, one per location."""
        return torch.tanh(self.net(_per_location_input(features, self.dims)))


class PrimitiveCritic(nn.Module):
    """Twin Q heads scoring a motion at every location: two independent MLPs (TD3's clipped
    double-Q needs their errors to be uncorrelated, so no shared trunk)."""

    def __init__(self, token_dim: int, local_dim: int, global_dim: int, hidden: int = 256,
                 motion_dim: int = 3):
        super().__init__()
        _check_dims(token_dim, local_dim, global_dim, hidden, motion_dim)
        self.dims = (token_dim, local_dim, global_dim)
        self.motion_dim = motion_dim
        in_dim = token_dim + local_dim + global_dim + motion_dim
        self.q1 = _mlp(in_dim, hidden, 1)
        self.q2 = _mlp(in_dim, hidden, 1)

    def forward(self, features: Features,
                motions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(q1, q2), each (B, L): the value of doing `motions[b, i]` at location i of state b."""
        x = _per_location_input(features, self.dims)
        if motions.dim() != 3 or motions.shape[:2] != x.shape[:2] \
                or motions.shape[2] != self.motion_dim:
            raise ValueError(f"motions: expected shape {(*x.shape[:2], self.motion_dim)}, got "
                             f"{tuple(motions.shape)}")
        x = torch.cat([x, motions.to(x.dtype)], dim=-1)
        return self.q1(x).squeeze(-1), self.q2(x).squeeze(-1)
