"""Running statistics for PPO: observation normalisation and reward scaling (pure torch).

One RunningMeanStd serves both, as a module with buffers: the agent's context normaliser is
part of the agent's state_dict (so policy checkpoints carry it), and the trainer checkpoints
the reward scaler's the same way.
"""

from __future__ import annotations

import torch
from torch import nn


class RunningMeanStd(nn.Module):
    """Mean/variance over everything seen so far (parallel-merge update, float64 buffers)."""

    def __init__(self, shape: tuple[int, ...] = (), epsilon: float = 1e-4):
        super().__init__()
        self.register_buffer("mean", torch.zeros(shape, dtype=torch.float64))
        self.register_buffer("var", torch.ones(shape, dtype=torch.float64))
        # A tiny prior count: the first batch then sets the statistics almost alone.
        self.register_buffer("count", torch.tensor(epsilon, dtype=torch.float64))

    @torch.no_grad()
    def update(self, x: torch.Tensor) -> None:
        x = x.detach().to(torch.float64).reshape(-1, *self.mean.shape)
        batch_mean, batch_var, n = x.mean(0), x.var(0, unbiased=False), x.shape[0]
        delta, total = batch_mean - self.mean, self.count + n
        self.var.copy_((self.var * self.count + batch_var * n
                        + delta ** 2 * self.count * n / total) / total)
        self.mean.add_(delta * n / total)
        self.count.copy_(total)

    def normalize(self, x: torch.Tensor, clip: float = 10.0) -> torch.Tensor:
        z = (x - self.mean.to(x.dtype)) / torch.sqrt(self.var.to(x.dtype) + 1e-8)
        return z.clamp(-clip, clip)


class RewardScaler(nn.Module):
    """Divides rewards by the running std of the discounted return (per env), as the authors do."""

    def __init__(self, num_envs: int, gamma: float):
        super().__init__()
        self.gamma = gamma
        self.register_buffer("returns", torch.zeros(num_envs, dtype=torch.float64))
        self.stats = RunningMeanStd(())

    @torch.no_grad()
    def forward(self, rewards: torch.Tensor, dones: torch.Tensor) -> torch.Tensor:
        self.returns.mul_(self.gamma).add_(rewards.to(torch.float64))
        self.stats.update(self.returns)
        self.returns.mul_((~dones.bool()).to(torch.float64))
        return rewards / torch.sqrt(self.stats.var.to(rewards.dtype) + 1e-8)
