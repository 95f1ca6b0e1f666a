"""A compact PPO (pure torch) with the authors' settings.

Why our own instead of a library: the loss has three non-standard parts the authors rely on — a
bound loss on the Gaussian mean beyond |mu| > 1.1, a KL-adaptive learning rate with an early stop
inside the update, and value bootstrapping on time-outs — and the policy takes dict observations
through a frozen encoder; TorchRL/rsl_rl would each need adapters around all of that, and ~150
lines here are easier to read and test.

Settings (PPOConfig defaults): gamma 0.99, lambda 0.95, clip 0.3, 8 epochs, lr 3e-4 adapted to
a KL target 0.016 (x1.5 below half, /1.5 above twice the target, bounded to [1e-6, 1e-2]), early
stop when the approximate KL exceeds 1.5 x target (the first minibatch of an update always
steps), loss 0.5 x surrogate + 2.0 x (0.5 x value MSE) + 0.02 x bound loss (the authors'
k_pi, k_val, k_bound), gradient clip 1.0, no entropy bonus. PPOConfig's docstring says
which numbers are the paper's and which the authors' code's.
"""

from __future__ import annotations

from typing import Callable

import torch
from torch import nn

from corn_drake.config.training import PPOConfig

Obs = dict[str, torch.Tensor]


def compute_gae(rewards: torch.Tensor, values: torch.Tensor, terminated: torch.Tensor,
                truncated: torch.Tensor, final_values: torch.Tensor, last_values: torch.Tensor,
                gamma: float, lam: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Advantages and returns for (T, N) rollouts.

    `final_values[t]` is V of the last observation of an episode cut at step t (time-out); its
    discounted value is added to the reward there, as the authors do, and the episode then ends.
    `last_values` (N,) bootstraps the step after the rollout.
    """
    T = rewards.shape[0]
    timeout = truncated.bool() & ~terminated.bool()
    r = rewards + gamma * final_values * timeout
    done = (terminated.bool() | truncated.bool()).to(rewards.dtype)
    adv = torch.zeros_like(rewards)
    next_value, next_adv = last_values, torch.zeros_like(last_values)
    for t in reversed(range(T)):
        delta = r[t] + gamma * next_value * (1 - done[t]) - values[t]
        next_adv = delta + gamma * lam * (1 - done[t]) * next_adv
        adv[t] = next_adv
        next_value = values[t]
    return adv, adv + values


def gaussian_log_prob(mu: torch.Tensor, log_std: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    return torch.distributions.Normal(mu, log_std.exp()).log_prob(actions).sum(-1)


class PPO:
    """`policy(obs) -> (mu, value)` with a `log_std` parameter; `update` takes flat batches."""

    def __init__(self, policy: nn.Module, cfg: PPOConfig | None = None):
        self.policy = policy
        self.cfg = cfg or PPOConfig()
        self.lr = self.cfg.lr
        critic = list(policy.critic_parameters()) if hasattr(policy, "critic_parameters") else []
        if self.cfg.separate_critic and not critic:
            raise ValueError("ppo.separate_critic needs a policy built with a separate critic "
                             "head (TeacherAgent(..., separate_critic=True))")
        if critic and not self.cfg.separate_critic:
            raise ValueError("the policy has a separate critic head but ppo.separate_critic is off")
        if critic and not self.cfg.critic_lr > 0:
            raise ValueError(f"ppo.critic_lr must be > 0, got {self.cfg.critic_lr}")
        actor = (policy.actor_parameters() if critic
                 else [p for p in policy.parameters() if p.requires_grad])
        self.actor_params, self.critic_params = actor, critic
        self.optimizer = torch.optim.Adam(actor, lr=self.lr)
        # Its own Adam at a fixed lr: the KL rule and the early stop are about the policy.
        self.critic_optimizer = torch.optim.Adam(critic, lr=self.cfg.critic_lr) if critic else None

    def _set_lr(self, kl: float) -> None:
        c = self.cfg
        if kl > 2.0 * c.kl_target:
            self.lr = max(self.lr / 1.5, c.lr_min)
        elif kl < 0.5 * c.kl_target:
            self.lr = min(self.lr * 1.5, c.lr_max)
        self._apply_lr()

    def _apply_lr(self) -> None:
        for group in self.optimizer.param_groups:
            group["lr"] = self.lr

    def losses(self, obs: Obs, actions, old_log_prob, advantages, returns) -> dict[str, torch.Tensor]:
        c = self.cfg
        mu, value = self.policy(obs)
        log_prob = gaussian_log_prob(mu, self.policy.log_std, actions)
        log_ratio = log_prob - old_log_prob
        ratio = log_ratio.exp()
        surrogate = -torch.min(ratio * advantages,
                               ratio.clamp(1 - c.clip, 1 + c.clip) * advantages).mean()
        value_loss = 0.5 * (value - returns).pow(2).mean()
        bound = (torch.relu(mu - c.bound_limit).pow(2) + torch.relu(-c.bound_limit - mu).pow(2))
        bound_loss = bound.sum(-1).mean()
        total = c.policy_coef * surrogate + c.value_coef * value_loss + c.bound_coef * bound_loss
        with torch.no_grad():
            kl = ((ratio - 1) - log_ratio).mean()
        return {"total": total, "surrogate": surrogate, "value": value_loss, "bound": bound_loss,
                "kl": kl}

    def update(self, obs: Obs, actions: torch.Tensor, old_log_prob: torch.Tensor,
               advantages: torch.Tensor, returns: torch.Tensor,
               generator: torch.Generator | None = None) -> dict[str, float]:
        """One PPO update on flat tensors (B, ...); returns statistics.

        `minibatches` counts the policy's optimiser steps. With a separate critic, the critic
        steps on every minibatch of every epoch (`critic_steps`), also after the policy's early
        stop; with a shared one, the update ends at the stop."""
        c = self.cfg
        advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
        n = actions.shape[0]
        stats = {"minibatches": 0, "critic_steps": 0, "early_stop": 0.0}
        last: dict[str, torch.Tensor] = {}
        separate = self.critic_optimizer is not None
        for _ in range(c.epochs):
            # Drawn on the CPU generator (the run's RNG stream on any device), then moved.
            order = torch.randperm(n, generator=generator).to(actions.device)
            for idx in order.chunk(c.minibatches):
                mb_obs = {k: v[idx] for k, v in obs.items()}
                last = self.losses(mb_obs, actions[idx], old_log_prob[idx], advantages[idx],
                                   returns[idx])
                actor_steps = not stats["early_stop"]
                # The first minibatch of an update sees the unchanged policy (KL = 0): it always
                # steps and leaves the lr alone. Later ones adapt the lr, and stop the update
                # when the policy has already moved too far.
                # An update that has to stop also lowers the lr: with the stop (1.5x target)
                # below the lr-decrease threshold (2x), small early-minibatch KLs otherwise
                # ratchet the lr up to lr_max while every update is cut short (seen in a probe).
                if actor_steps and stats["minibatches"] > 0:
                    kl = float(last["kl"])
                    if kl > c.kl_stop_factor * c.kl_target:
                        self.lr = max(self.lr / 1.5, c.lr_min)
                        self._apply_lr()
                        stats["early_stop"] = 1.0
                        actor_steps = False
                    else:
                        self._set_lr(kl)
                if not actor_steps and not separate:
                    break
                self.optimizer.zero_grad()
                if separate:
                    self.critic_optimizer.zero_grad()
                # A separate critic's loss reaches only its own head (detached features), so one
                # backward serves both; after the policy's stop only the value term is left.
                (last["total"] if actor_steps else c.value_coef * last["value"]).backward()
                if separate:
                    nn.utils.clip_grad_norm_(self.critic_params, c.max_grad_norm)
                    self.critic_optimizer.step()
                    stats["critic_steps"] += 1
                if actor_steps:
                    nn.utils.clip_grad_norm_(self.actor_params, c.max_grad_norm)
                    self.optimizer.step()
                    stats["minibatches"] += 1
            if stats["early_stop"] and not separate:
                break
        stats.update({k: float(v.detach()) for k, v in last.items()})
        stats["lr"] = self.lr
        return stats

    def state_dict(self) -> dict:
        state = {"optimizer": self.optimizer.state_dict(), "lr": self.lr}
        if self.critic_optimizer is not None:
            state["critic_optimizer"] = self.critic_optimizer.state_dict()
        return state

    def load_state_dict(self, state: dict) -> None:
        if (self.critic_optimizer is not None) != ("critic_optimizer" in state):
            raise ValueError("the saved PPO state and this run disagree on ppo.separate_critic")
        if any(g.get("lr_scale", 1.0) != 1.0 for g in state["optimizer"]["param_groups"]):
            # Per-layer lr groups: a state saved with the retired ppo.fan_in_lr_ref.
            raise ValueError("the saved PPO state was written with ppo.fan_in_lr_ref, which was "
                             "retired (config/retired.py); it cannot be resumed")
        self.optimizer.load_state_dict(state["optimizer"])
        if self.critic_optimizer is not None:
            self.critic_optimizer.load_state_dict(state["critic_optimizer"])
        self.lr = state["lr"]
        self._apply_lr()


def sample_actions(policy: Callable, obs: Obs, generator: torch.Generator | None = None):
    """(actions, log_prob, value) from the current policy, without gradients."""
    with torch.no_grad():
        mu, value = policy(obs)
    # The noise comes from the CPU generator whatever the device: a run draws the same
    # stream on cpu and cuda, and its checkpoint holds that generator's state.
    return actions_from_noise(policy, obs, torch.randn(mu.shape, generator=generator),
                              (mu, value))


def actions_from_noise(policy: Callable, obs: Obs, noise: torch.Tensor, forward=None):
    """(actions, log_prob, value) without gradients: mean + exp(log_std) * `noise` (unit
    Gaussian draws shaped like the actions, on any device). `forward`: policy(obs) if already
    computed. The learner draws the noise, so envs stepped anywhere act with the same draws."""
    with torch.no_grad():
        mu, value = policy(obs) if forward is None else forward
        actions = mu + policy.log_std.exp() * noise.to(mu.device, mu.dtype)
        return actions, gaussian_log_prob(mu, policy.log_std, actions), value
