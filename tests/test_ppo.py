"""PPO on hand-made batches: GAE with time-outs, loss decreases, KL early stop, bound loss."""

import pytest
import torch
from torch import nn

from corn_drake.errors import InputError
from corn_drake.nn.policy import CrossAttentionActorCritic, MLPActorCritic
from corn_drake.rl.normalization import RewardScaler, RunningMeanStd
from corn_drake.config.training import PPOConfig
from corn_drake.rl.ppo.ppo import PPO, compute_gae, sample_actions


class _FlatPolicy(nn.Module):
    """The teacher's MLP trunk on a flat observation `x` (as both features and context)."""

    def __init__(self, obs_dim: int = 4, action_dim: int = 3):
        super().__init__()
        self.net = MLPActorCritic(feature_dim=obs_dim, context_dim=obs_dim, action_dim=action_dim)
        self.log_std = self.net.log_std

    def forward(self, obs):
        return self.net(obs["x"], obs["x"])


def _cfg(**settings) -> PPOConfig:
    """PPO settings for _FlatPolicy, whose value comes from its trunk (no separate critic head:
    ppo.separate_critic off)."""
    return PPOConfig(separate_critic=False, **settings)


def _batch(policy, n=256, seed=0):
    g = torch.Generator().manual_seed(seed)
    obs = {"x": torch.randn(n, 4, generator=g)}
    actions, log_prob, _ = sample_actions(policy, obs, g)
    # Reward the first action dimension's sign agreeing with the first observation's.
    advantages = torch.sign(actions[:, 0]) * torch.sign(obs["x"][:, 0])
    returns = advantages.clone()
    return obs, actions, log_prob, advantages, returns


def test_gae_matches_hand_computation_with_timeout_bootstrap():
    r = torch.tensor([[1.0], [1.0], [1.0]])
    v = torch.tensor([[0.5], [0.5], [0.5]])
    term = torch.tensor([[0.0], [0.0], [0.0]])
    trunc = torch.tensor([[0.0], [1.0], [0.0]])  # episode cut after step 1
    final_v = torch.tensor([[0.0], [2.0], [0.0]])
    last_v = torch.tensor([3.0])
    g, lam = 0.9, 0.5
    adv, ret = compute_gae(r, v, term, trunc, final_v, last_v, g, lam)
    d2 = 1 + g * 3.0 - 0.5
    d1 = 1 + g * 2.0 - 0.5  # bootstrapped with the cut episode's final value, then stops
    d0 = 1 + g * 0.5 - 0.5
    expected = torch.tensor([[d0 + g * lam * d1], [d1], [d2]])
    torch.testing.assert_close(adv, expected)
    torch.testing.assert_close(ret, expected + v)


def test_update_lowers_the_clipped_loss():
    torch.manual_seed(0)
    policy = _FlatPolicy()
    ppo = PPO(policy, _cfg(epochs=4, minibatches=4, kl_target=1.0))
    obs, actions, logp, adv, ret = _batch(policy)
    norm_adv = (adv - adv.mean()) / (adv.std() + 1e-8)
    before = ppo.losses(obs, actions, logp, norm_adv, ret)["surrogate"].item()
    stats = ppo.update(obs, actions, logp, adv, ret, torch.Generator().manual_seed(1))
    after = ppo.losses(obs, actions, logp, norm_adv, ret)["surrogate"].item()
    assert stats["minibatches"] == 16 and stats["early_stop"] == 0.0
    assert after < before - 0.05


def test_kl_early_stop_and_lr_adaptation():
    torch.manual_seed(0)
    policy = _FlatPolicy()
    cfg = _cfg(epochs=8, minibatches=4, lr=1e-2, kl_target=1e-6)
    ppo = PPO(policy, cfg)
    obs, actions, logp, adv, ret = _batch(policy)
    stats = ppo.update(obs, actions, logp, adv, ret, torch.Generator().manual_seed(1))
    # The first minibatch always steps; a big step then trips the stop.
    assert stats["early_stop"] == 1.0
    assert 1 <= stats["minibatches"] < 32
    assert stats["kl"] > cfg.kl_stop_factor * cfg.kl_target
    # KL below half the target raises the lr by 1.5, above twice lowers it (bounded).
    ppo2 = PPO(_FlatPolicy(), _cfg(lr=1e-3))
    ppo2._set_lr(0.0)
    assert abs(ppo2.lr - 1.5e-3) < 1e-12
    ppo2._set_lr(1.0)
    assert abs(ppo2.lr - 1e-3) < 1e-12


def test_bound_loss_only_beyond_the_limit():
    policy = _FlatPolicy()
    ppo = PPO(policy, _cfg())
    obs = {"x": torch.zeros(2, 4)}
    with torch.no_grad():
        policy.net.heads.actor[-1].bias.copy_(torch.tensor([1.5, 0.0, -1.0]))
        policy.net.heads.actor[-1].weight.zero_()
    losses = ppo.losses(obs, torch.zeros(2, 3), torch.zeros(2), torch.zeros(2), torch.zeros(2))
    assert abs(losses["bound"].item() - 0.4 ** 2) < 1e-6


def test_cross_attention_policy_shapes_and_weights():
    policy = CrossAttentionActorCritic()
    tokens, ctx = torch.randn(5, 17, 128), torch.randn(5, 48)
    mu, value = policy(tokens, ctx)
    assert mu.shape == (5, 20) and value.shape == (5,)
    _, weights = policy.attend(tokens, ctx)
    assert weights.shape == (5, 16, 17)
    torch.testing.assert_close(weights.sum(-1), torch.ones(5, 16))
    n_params = sum(p.numel() for p in policy.parameters())
    assert 1.2e6 < n_params < 1.6e6  # ~1.39 M in the authors' model


def test_running_stats_and_reward_scaler():
    rms = RunningMeanStd((3,))
    data = torch.randn(1000, 3) * torch.tensor([1.0, 2.0, 3.0]) + 5
    for chunk in data.chunk(10):
        rms.update(chunk)
    torch.testing.assert_close(rms.mean.float(), data.mean(0), atol=1e-3, rtol=0)
    torch.testing.assert_close(rms.var.float(), data.var(0, unbiased=False), atol=1e-2, rtol=1e-3)
    scaler = RewardScaler(2, 0.99)
    out = scaler(torch.tensor([2.0, 4.0]), torch.tensor([False, True]))
    assert out.shape == (2,) and torch.isfinite(out).all()
    assert scaler.returns[1] == 0  # reset where the episode ended


def test_the_agent_normalises_its_context_with_the_one_running_mean_std():
    """The agent's context normaliser is a RunningMeanStd module: its statistics are those of
    everything it saw, they travel in the agent's state_dict, and a loaded agent normalises
    the same way."""
    from corn_drake.contract import CONTEXT_DIM
    from corn_drake.rl.ppo.agent import TeacherAgent

    torch.manual_seed(0)
    agent = TeacherAgent("state")
    assert isinstance(agent.context_normalizer, RunningMeanStd)
    data = torch.randn(600, CONTEXT_DIM) * 3 + 2
    for chunk in data.chunk(3):
        agent.update_normalizer(chunk)
    torch.testing.assert_close(agent.context_normalizer.mean.float(), data.mean(0), atol=1e-4, rtol=0)
    state = agent.state_dict()
    assert {"context_normalizer.mean", "context_normalizer.var", "context_normalizer.count"} <= set(state)
    loaded = TeacherAgent("state")
    loaded.load_state_dict(state)
    probe = torch.randn(4, CONTEXT_DIM)
    torch.testing.assert_close(loaded.normalized_context(probe), agent.normalized_context(probe))
    assert not torch.allclose(TeacherAgent("state").normalized_context(probe),
                              agent.normalized_context(probe))
    # A checkpoint from before the normaliser was a module is refused, naming the file.
    old = {k: v for k, v in state.items() if not k.startswith("context_normalizer.")}
    old.update(ctx_mean=torch.zeros(CONTEXT_DIM), ctx_var=torch.ones(CONTEXT_DIM))
    with pytest.raises(InputError, match="old_run/last.pt.*train the run again"):
        loaded.load_saved_state(old, "old_run/last.pt")


def test_reward_scaler_state_round_trips():
    first = RewardScaler(3, 0.99)
    rewards = torch.tensor([[1.0, -2.0, 0.5], [0.3, 0.1, -1.0], [2.0, 2.0, 2.0]])
    dones = torch.tensor([[False, False, True], [False, True, False], [False, False, False]])
    first(rewards[0], dones[0])
    second = RewardScaler(3, 0.99)
    second.load_state_dict(first.state_dict())
    for r, d in zip(rewards[1:], dones[1:]):
        torch.testing.assert_close(second(r, d), first(r, d))
    torch.testing.assert_close(second.returns, first.returns)


def test_lr_goes_down_when_updates_overshoot_the_kl_target():
    torch.manual_seed(0)
    policy = _FlatPolicy()
    ppo = PPO(policy, _cfg(epochs=8, minibatches=4, lr=5e-3, kl_target=1e-4))
    obs, actions, logp, adv, ret = _batch(policy)
    ppo.update(obs, actions, logp, adv, ret, torch.Generator().manual_seed(1))
    assert ppo.lr < 5e-3  # overshooting KL lowers the lr instead of pinning it at the maximum


def test_an_update_cut_short_does_not_leave_a_raised_lr(monkeypatch):
    """KLs small at first (lr raised) then past the stop (1.5x target) but below the decrease
    threshold (2x): the stop must give the raise back, or the lr ratchets up update after
    update while every update is cut short."""
    torch.manual_seed(0)
    policy = _FlatPolicy()
    cfg = _cfg(epochs=8, minibatches=4, lr=1e-3, kl_target=0.016)
    ppo = PPO(policy, cfg)
    real_losses = ppo.losses
    kls = iter([0.0, 0.001, 0.030])  # 0.030: above the stop (0.024), below 2x target (0.032)

    def scripted(*args):
        out = real_losses(*args)
        out["kl"] = torch.tensor(next(kls))
        return out

    monkeypatch.setattr(ppo, "losses", scripted)
    obs, actions, logp, adv, ret = _batch(policy)
    stats = ppo.update(obs, actions, logp, adv, ret, torch.Generator().manual_seed(1))
    assert stats["early_stop"] == 1.0 and stats["minibatches"] == 2
    assert ppo.lr <= cfg.lr + 1e-12
    assert all(g["lr"] == ppo.lr for g in ppo.optimizer.param_groups)


def _reach_rollout(policy, x, generator, steps=10):
    """Points move by 0.1 x clipped action; reward = decrease of the distance to the origin."""
    buf = {k: [] for k in ("obs", "actions", "logp", "values", "rewards")}
    for _ in range(steps):
        obs = {"x": x}
        actions, logp, values = sample_actions(policy, obs, generator)
        nxt = x + 0.1 * actions.clamp(-1, 1)
        for key, value in (("obs", x), ("actions", actions), ("logp", logp), ("values", values),
                           ("rewards", x.norm(dim=1) - nxt.norm(dim=1))):
            buf[key].append(value)
        x = nxt
    with torch.no_grad():
        last_values = policy({"x": x})[1]
    stack = {k: torch.stack(v) for k, v in buf.items()}
    zeros = torch.zeros_like(stack["rewards"])
    truncated = zeros.clone()
    truncated[-1] = 1.0  # the episode is cut by the time limit: bootstrap from V(last)
    final_values = zeros.clone()
    final_values[-1] = last_values
    return stack, zeros, truncated, final_values, last_values


def test_ppo_with_the_paper_settings_learns_a_reach_task():
    """Closed loop (rollout -> GAE -> update), the teacher's trunk and PPOConfig defaults (its
    value from the trunk): a policy that drives 2-D points to the origin must come out of 40
    updates."""
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(0)
    policy = _FlatPolicy(obs_dim=2, action_dim=2)  # a 2-D point: obs = its position
    cfg = _cfg()
    ppo = PPO(policy, cfg)

    def final_distance() -> float:
        x = torch.rand(256, 2, generator=torch.Generator().manual_seed(99)) * 2 - 1
        with torch.no_grad():
            for _ in range(10):
                x = x + 0.1 * policy({"x": x})[0].clamp(-1, 1)
        return float(x.norm(dim=1).mean())

    before = final_distance()
    for _ in range(40):
        x = torch.rand(64, 2, generator=g) * 2 - 1
        stack, term, trunc, final_v, last_v = _reach_rollout(policy, x, g)
        adv, ret = compute_gae(stack["rewards"], stack["values"], term, trunc, final_v, last_v,
                               cfg.gamma, cfg.gae_lambda)
        ppo.update({"x": stack["obs"].flatten(0, 1)}, stack["actions"].flatten(0, 1),
                   stack["logp"].flatten(0, 1), adv.flatten(), ret.flatten(), g)
    after = final_distance()
    # The start points average ~0.77 from the origin; a policy that moves toward it at full
    # speed for 10 steps ends near 0.1.
    assert after < 0.5 * before, (before, after)


def test_loss_weights_are_the_authors():
    """total = k_pi * surrogate + k_val * 0.5 * MSE(value) + k_bound * bound, with the authors'
    k_pi 0.5, k_val 2.0, k_bound 0.02 (their ppo.py), computed here independently of
    PPO.losses on a fixed batch whose actions reach past the bound."""
    torch.manual_seed(0)
    policy = _FlatPolicy()
    obs, actions, logp, adv, _ = _batch(policy, n=64)
    returns = torch.linspace(-2.0, 3.0, 64)  # far from the untrained values: a big value term
    with torch.no_grad():
        policy.net.heads.actor[-1].bias.copy_(torch.tensor([1.6, -1.3, 0.2]))
    losses = PPO(policy, _cfg()).losses(obs, actions, logp, adv, returns)
    with torch.no_grad():
        mu, value = policy(obs)
        std = policy.log_std.exp()
        new_logp = (-((actions - mu) ** 2) / (2 * std ** 2) - std.log()
                    - 0.5 * torch.log(torch.tensor(2 * torch.pi))).sum(-1)
        ratio = (new_logp - logp).exp()
        surrogate = -torch.min(ratio * adv, ratio.clamp(0.7, 1.3) * adv).mean()
        value_mse = ((value - returns) ** 2).mean()
        bound = ((mu - 1.1).clamp(min=0) ** 2 + (-1.1 - mu).clamp(min=0) ** 2).sum(-1).mean()
    assert value_mse > 1.0 and bound > 0.01  # each term weighs in the total
    expected = 0.5 * surrogate + 2.0 * 0.5 * value_mse + 0.02 * bound
    torch.testing.assert_close(losses["total"].detach(), expected, rtol=1e-5, atol=1e-6)


def test_a_state_saved_with_per_layer_lr_groups_is_refused():
    """The retired ppo.fan_in_lr_ref wrote lr scales into the optimiser's groups: such a state is
    refused in one line; one written with every scale 1 (that option off) still loads."""
    plain = PPO(_FlatPolicy(), _cfg())
    saved = plain.state_dict()
    groups = saved["optimizer"]["param_groups"]
    old = {"optimizer": {**saved["optimizer"], "param_groups": [{**g, "lr_scale": 1.0}
                                                                for g in groups]}, "lr": 2e-4}
    again = PPO(_FlatPolicy(), _cfg())
    again.load_state_dict(old)
    assert again.optimizer.param_groups[0]["lr"] == pytest.approx(2e-4)
    scaled = {**old, "optimizer": {**old["optimizer"], "param_groups": [
        {**g, "lr_scale": 0.25} for g in groups]}}
    with pytest.raises(ValueError, match="fan_in_lr_ref, which was retired"):
        PPO(_FlatPolicy(), _cfg()).load_state_dict(scaled)
