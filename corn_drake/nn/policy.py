"""Teacher policy heads (pure torch): cross-attention over encoder tokens, and the baselines.

CrossAttentionActorCritic (the paper's `corn` / `e2e` head): 16 query tokens from
Linear(48 -> 16 x 128) on the context (contract.CONTEXT_KEYS: goal 9, previous action 20,
joints 14, physics 5; sizes from contract.py) attend
(single head) over the encoder's 17 x 128 tokens; the 2048 attended features plus the context
go through MLP 2096 -> 512 -> 256 -> 128 (LayerNorm + ELU), then an actor 128 -> 64 -> 20 with a
learned state-independent log-std (init 0) and a critic 128 -> 64 -> 1.
MLPActorCritic: the same trunk on a flat feature vector (the `state` baseline: context + object
bounding-box keypoints + hand pose; the `pn` baseline: context + a PointNet global feature).
"""

from __future__ import annotations

import torch
from torch import nn

from corn_drake.contract import ACTION_DIM, CONTEXT_DIM


def gaussian_action(mean: torch.Tensor, log_std: torch.Tensor,
                    unit_noise: torch.Tensor | None = None) -> torch.Tensor:
    """The action a Gaussian policy executes, clipped to [-1, 1]: its mean, or with `unit_noise`
    (N(0, 1) draws shaped like the mean, from the caller) the sample mean + exp(log_std) * noise.
    One definition for the teacher's agent and the student's evaluation system."""
    if unit_noise is not None:
        mean = mean + log_std.exp() * unit_noise.to(mean).reshape(mean.shape)
    return mean.clamp(-1, 1)


def mlp(sizes: list[int], final_activation: bool = True) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        layers.append(nn.Linear(a, b))
        if final_activation or i < len(sizes) - 2:
            layers += [nn.LayerNorm(b), nn.ELU()]
    return nn.Sequential(*layers)


class _Heads(nn.Module):
    """Shared trunk output (128) -> Gaussian actor and value critic."""

    def __init__(self, trunk_in: int, action_dim: int = ACTION_DIM):
        super().__init__()
        self.trunk = mlp([trunk_in, 512, 256, 128])
        self.actor = mlp([128, 64, action_dim], final_activation=False)
        self.critic = mlp([128, 64, 1], final_activation=False)
        self.log_std = nn.Parameter(torch.zeros(action_dim))

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = self.trunk(features)
        return self.actor(h), self.critic(h).squeeze(-1)


class CrossAttentionActorCritic(nn.Module):
    def __init__(self, token_dim: int = 128, num_queries: int = 16, context_dim: int = CONTEXT_DIM,
                 action_dim: int = ACTION_DIM):
        super().__init__()
        self.num_queries, self.token_dim = num_queries, token_dim
        self.query = nn.Linear(context_dim, num_queries * token_dim)
        self.key_value = nn.Linear(token_dim, 2 * token_dim)
        self.heads = _Heads(num_queries * token_dim + context_dim, action_dim)
        self.log_std = self.heads.log_std

    def attend(self, tokens: torch.Tensor, context: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(attended features (B, Q*D), attention weights (B, Q, T))."""
        q = self.query(context).view(-1, self.num_queries, self.token_dim)
        k, v = self.key_value(tokens).chunk(2, dim=-1)
        weights = torch.softmax(q @ k.transpose(1, 2) / self.token_dim ** 0.5, dim=-1)
        return (weights @ v).flatten(1), weights

    def forward(self, tokens: torch.Tensor, context: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.forward_with_weights(tokens, context)[:2]

    def forward_with_weights(self, tokens: torch.Tensor, context: torch.Tensor
                             ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(action mean, value, attention weights (B, Q, T)) from one pass: what the policy
        attended to when it chose that action (nn/attention.py turns it into patch scores)."""
        attended, weights = self.attend(tokens, context)
        mu, value = self.heads(torch.cat([attended, context], dim=-1))
        return mu, value, weights


class MLPActorCritic(nn.Module):
    def __init__(self, feature_dim: int, context_dim: int = CONTEXT_DIM, action_dim: int = ACTION_DIM):
        super().__init__()
        self.heads = _Heads(feature_dim + context_dim, action_dim)
        self.log_std = self.heads.log_std

    def forward(self, features: torch.Tensor, context: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.heads(torch.cat([features, context], dim=-1))
