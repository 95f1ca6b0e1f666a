"""Running statistics for PPO: observation normalisation and reward scaling (pure torch)."""

from __future__ import annotations

import torch


class RunningMeanStd:
    """Mean/variance over everything seen so far (parallel-merge update, float64)."""

    def __init__(self, shape: tuple[int, ...] = (), epsilon: float = 1e-4):
        self.mean = torch.zeros(shape, dtype=torch.float64)
        self.var = torch.ones(shape, dtype=torch.float64)
        self.count = epsilon

    def update(self, x: torch.Tensor) -> None:
        x = x.detach().to(torch.float64).reshape(-1, *self.mean.shape)
        batch_mean, batch_var, n = x.mean(0), x.var(0, unbiased=False), x.shape[0]
        delta = batch_mean - self.mean
        total = self.count + n
        self.mean = self.mean + delta * n / total
        self.var = (self.var * self.count + batch_var * n + delta ** 2 * self.count * n / total) / total
        self.count = total

    def normalize(self, x: torch.Tensor, clip: float = 10.0) -> torch.Tensor:
        z = (x - self.mean.to(x.dtype)) / torch.sqrt(self.var.to(x.dtype) + 1e-8)
        return z.clamp(-clip, clip)

    def state_dict(self) -> dict:
        return {"mean": self.mean, "var": self.var, "count": self.count}

    def load_state_dict(self, state: dict) -> None:
        self.mean, self.var, self.count = state["mean"], state["var"], float(state["count"])


class RewardScaler:
    """Divides rewards by the running std of the discounted return (per env), as the authors do."""

    def __init__(self, num_envs: int, gamma: float):
        self.gamma = gamma
        self.returns = torch.zeros(num_envs, dtype=torch.float64)
        self.stats = RunningMeanStd(())

    def __call__(self, rewards: torch.Tensor, dones: torch.Tensor) -> torch.Tensor:
        self.returns = self.returns * self.gamma + rewards.to(torch.float64)
        self.stats.update(self.returns)
        self.returns = self.returns * (~dones.bool()).to(torch.float64)
        return (rewards / torch.sqrt(self.stats.var.to(rewards.dtype) + 1e-8))

    def state_dict(self) -> dict:
        return {"returns": self.returns, "stats": self.stats.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        self.returns = state["returns"]
        self.stats.load_state_dict(state["stats"])
