"""TeacherAgent: observation dict -> (action mean, value), for every policy variant.

Variants (the paper's names): `corn` — frozen pretrained patch encoder + cross-attention head;
`e2e` — the same encoder randomly initialised and trained by PPO; `pn` — a frozen pretrained
PointNet's global feature + MLP head; `state` — no cloud, the object's bounding-box keypoints
and the hand pose + MLP head. Cloud, hand pose and keypoints use fixed normalisation
((x - (0, 0, 0.55)) / 0.4, as the encoder was pretrained with); the 48-D context (goal, previous
action, joints, physics) uses running mean/std kept in buffers, so checkpoints carry them.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import torch
from torch import nn

from corn_drake.nn.policy import CONTEXT_DIM, CrossAttentionActorCritic, MLPActorCritic

POLICY_KINDS = ("corn", "e2e", "state", "pn")
CONTEXT_KEYS = ("goal", "previous_action", "robot_state", "physics")
CLOUD_CENTER = torch.tensor([0.0, 0.0, 0.55])
CLOUD_SCALE = 0.4
STATE_FEATURE_DIM = 24 + 9  # bounding-box keypoints + hand state, for the `state` baseline

# An encoder maps (normalised cloud (B, N, 3), normalised hand state (B, 9)) to tokens
# (B, T, D) for `corn` / `e2e`, or to a global feature (B, F) for `pn`.
Encoder = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


def normalize_points(x: torch.Tensor) -> torch.Tensor:
    return (x - CLOUD_CENTER.to(x.dtype)) / CLOUD_SCALE


def normalize_hand(hand: torch.Tensor) -> torch.Tensor:
    return torch.cat([normalize_points(hand[..., :3]), hand[..., 3:]], dim=-1)


def obs_to_tensors(obs: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
    """Batched numpy observations -> float32 tensors, with the 48-D context assembled."""
    t = {k: torch.as_tensor(np.asarray(v), dtype=torch.float32) for k, v in obs.items()}
    t["context"] = torch.cat([t[k] for k in CONTEXT_KEYS], dim=-1)
    return t


class TeacherAgent(nn.Module):
    def __init__(self, kind: str, encoder: nn.Module | None = None, feature_dim: int | None = None):
        super().__init__()
        if kind not in POLICY_KINDS:
            raise ValueError(f"policy must be one of {POLICY_KINDS}, got {kind!r}")
        if kind != "state" and encoder is None:
            raise ValueError(f"policy {kind!r} needs an encoder")
        self.kind = kind
        self.encoder = encoder
        if encoder is not None and self.frozen_encoder:
            encoder.eval()
            for p in encoder.parameters():
                p.requires_grad_(False)
        if kind in ("corn", "e2e"):
            self.head = CrossAttentionActorCritic()
        elif kind == "pn":
            self.head = MLPActorCritic(feature_dim or 1024)
        else:
            self.head = MLPActorCritic(STATE_FEATURE_DIM)
        self.log_std = self.head.log_std
        self.register_buffer("ctx_mean", torch.zeros(CONTEXT_DIM, dtype=torch.float64))
        self.register_buffer("ctx_var", torch.ones(CONTEXT_DIM, dtype=torch.float64))
        self.register_buffer("ctx_count", torch.tensor(1e-4, dtype=torch.float64))
        # None: act() returns the Gaussian mean (evaluation's default). A generator: act()
        # samples from the policy, as during training (`corn-drake evaluate --stochastic`).
        self.action_noise: torch.Generator | None = None

    @property
    def frozen_encoder(self) -> bool:
        """True for corn / pn: PPO never trains the encoder, so its features can be cached."""
        return self.kind in ("corn", "pn")

    def update_normalizer(self, context: torch.Tensor) -> None:
        x = context.detach().to(torch.float64).reshape(-1, CONTEXT_DIM)
        mean, var, n = x.mean(0), x.var(0, unbiased=False), x.shape[0]
        delta, total = mean - self.ctx_mean, self.ctx_count + n
        self.ctx_mean += delta * n / total
        self.ctx_var.copy_((self.ctx_var * self.ctx_count + var * n
                            + delta ** 2 * self.ctx_count * n / total) / total)
        self.ctx_count.fill_(float(total))

    def normalized_context(self, context: torch.Tensor) -> torch.Tensor:
        z = (context - self.ctx_mean.float()) / torch.sqrt(self.ctx_var.float() + 1e-8)
        return z.clamp(-10, 10)

    def features(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        if self.kind == "state":
            # The hand pose too: corn/e2e/pn see it through the encoder's hand token, and
            # without it the state policy would have to learn the arm's kinematics from joints.
            keypoints = normalize_points(obs["object_keypoints"].reshape(-1, 8, 3)).flatten(1)
            return torch.cat([keypoints, normalize_hand(obs["hand_state"])], dim=-1)
        if self.frozen_encoder and "features" in obs:
            # Precomputed at collection time (rl/trainer.py): a frozen encoder would give the
            # same features again, and skipping it makes every PPO epoch much cheaper.
            return obs["features"]
        cloud, hand = normalize_points(obs["cloud"]), normalize_hand(obs["hand_state"])
        if self.kind == "e2e":
            return self.encoder(cloud, hand)
        with torch.no_grad():  # frozen: PPO never backpropagates into the encoder
            return self.encoder(cloud, hand)

    def forward(self, obs: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        return self.head(self.features(obs), self.normalized_context(obs["context"]))

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """Action clipped to [-1, 1], for one or many obs: the Gaussian mean, or a sample from
        the policy when `action_noise` holds a generator."""
        single = np.asarray(obs["goal"]).ndim == 1
        batch = {k: np.asarray(v)[None] for k, v in obs.items()} if single else obs
        with torch.no_grad():
            mu, _ = self(obs_to_tensors(batch))
            if self.action_noise is not None:
                mu = mu + self.log_std.exp() * torch.randn(mu.shape, generator=self.action_noise)
        action = mu.clamp(-1, 1).numpy().astype(np.float64)
        return action[0] if single else action
