"""TD3 for a contact-primitive policy with a per-location critic (HACMan-style).

The action is hybrid: a discrete location i (one of L) and a continuous motion a_i. The actor
(corn_drake.nn.primitive_heads.PrimitiveActor) proposes a motion for EVERY location and the
critic scores every (location, motion) pair, so the discrete part needs no network of its own:
the policy acts on the per-location score Q1(s, i, actor(s)_i) — greedily by argmax, or, while
exploring, by sampling a softmax of the scores with a temperature (plus Gaussian motion noise).

Update (one call = one TD3 step on a replay batch):
  target  y = r + gamma (1 - done) min(Q1', Q2')(s', i*, a*_i*),
          a* = target actor's motions + clipped Gaussian noise (target policy smoothing);
          i* = argmax_i Q1(s', i, actor(s')_i), the online policy's greedy location in s'
          (chosen by the online networks, valued by the targets: Double DQN's decoupling,
          see update()), among the locations features["mask"] allows.
  critic  MSE of Q1 and Q2 at the taken (location, motion) against y (their sum).
  actor   every `policy_delay` critic steps: -mean over ALL locations of Q1(s, i, actor(s)_i)
          (HACMan trains the motion at every location, not only the chosen one, since each
          location's motion is a separate decision the critic can judge), then Polyak averaging
          of both target networks with tau.

The target noise is drawn from the learner's own torch.Generator, whose state is part of
`state_dict`, so a run resumed from a checkpoint continues bit-for-bit.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields

import numpy as np
import torch
from torch import nn

Features = Mapping[str, torch.Tensor]


def choosable(mask: torch.Tensor) -> torch.Tensor:
    """(B, L) bool: the locations a state may choose from, given its features["mask"] (B, L; 1
    usable, 0 not). A state with no usable location keeps all of them."""
    usable = torch.as_tensor(mask) > 0.5
    return usable | ~usable.any(dim=1, keepdim=True)


def masked(scores: torch.Tensor, features: Features) -> torch.Tensor:
    """`scores` (B, L) with the locations features["mask"] rules out (when the key is present;
    `choosable`) set to -inf, so no choice and no bootstrap target takes them: a location the
    policy never takes has a Q value nothing ever trained."""
    mask = features.get("mask") if isinstance(features, Mapping) else None
    if mask is None:
        return scores
    return scores.masked_fill(~choosable(mask).to(scores.device), float("-inf"))


@torch.no_grad()
def scores_and_motions(actor, critic, features: Features) -> tuple[torch.Tensor, torch.Tensor]:
    """(per-location scores Q1(s, i, actor(s)_i), -inf where features["mask"] rules a location
    out; the actor's motions): what the policy chooses by, from any copy of the networks."""
    motions = actor(features)
    q1, _ = critic(features, motions)
    return masked(q1, features), motions


def select_primitives(scored: tuple[torch.Tensor, torch.Tensor], *, greedy: bool,
                      temperature: float = 1.0, motion_noise: float = 0.0,
                      rng: np.random.Generator | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(location (B,) int64, motion (B, motion_dim) float32, scores (B, L) float32) from the
    per-location scores (-inf where masked) and motions of a batch of states (`scored`:
    scores_and_motions' pair). A free function so
    a collector holding only a copy of the actor and critic (a Ray worker,
    rl/primitive/collection.py) chooses exactly as the learner does.

    greedy: the best-scoring location and the actor's motion there. Otherwise the location
    is drawn from softmax(scores / temperature) and N(0, motion_noise) is added to the motion
    (clipped to [-1, 1]); all randomness comes from `rng`, so a seed repeats the choices.
    """
    if not greedy:
        if rng is None:
            raise ValueError("rng: exploring (greedy=False) needs a numpy Generator")
        if not (temperature > 0 and math.isfinite(temperature)):
            raise ValueError(f"temperature: expected a finite value > 0, got {temperature!r}")
        if not (motion_noise >= 0 and math.isfinite(motion_noise)):
            raise ValueError(f"motion_noise: expected a finite value >= 0, got "
                             f"{motion_noise!r}")
    q1, motions = scored
    scores = q1.cpu().numpy().astype(np.float32)
    motions = motions.cpu().numpy().astype(np.float32)
    batch = np.arange(scores.shape[0])
    if greedy:
        location = scores.argmax(axis=1).astype(np.int64)
        return location, motions[batch, location], scores
    # Softmax in float64 with the row max removed: no overflow for any score scale.
    logits = scores.astype(np.float64) / temperature
    probs = np.exp(logits - logits.max(axis=1, keepdims=True))
    cdf = np.cumsum(probs / probs.sum(axis=1, keepdims=True), axis=1)
    draws = rng.random(scores.shape[0])
    # Inverse-CDF sampling; the clip guards a cdf whose last entry rounds below 1.
    location = np.minimum((cdf < draws[:, None]).sum(axis=1),
                          scores.shape[1] - 1).astype(np.int64)
    motion = motions[batch, location]
    if motion_noise > 0:
        motion = motion + rng.normal(0.0, motion_noise, size=motion.shape)
    return location, np.clip(motion, -1.0, 1.0).astype(np.float32), scores


@dataclass
class TD3Settings:
    """Learner settings. The numbers are a primitive run's (PrimitiveTrainConfig's fields of the
    same names, the one place they are set, with why; `for_run`), all but the gradient clip.
    They are TD3's (Fujimoto et al. 2018) except gamma (0.9 there, for episodes of at most
    10 primitives) and the batch size.

    How HACMan (Zhou et al. 2023) differs, where we know it: it uses gamma 0.99, with short
    episodes of 10 primitives (so the horizon, not gamma, bounds the return); it explores by
    sampling the location from a softmax over the per-point Q values with a temperature (our
    `TD3Learner.select(greedy=False, temperature=...)`) rather than epsilon-greedy. Its other
    numbers (learning rates, noise, batch size) were not checked against its code here.
    """

    gamma: float
    tau: float
    actor_lr: float
    critic_lr: float
    policy_delay: int
    target_noise: float
    target_noise_clip: float
    batch_size: int  # what the caller samples from the replay per update
    # Max global gradient norm per network; a bootstrap target can spike early in training.
    grad_clip: float = 10.0

    @classmethod
    def for_run(cls, cfg, **changes) -> TD3Settings:
        """The settings of a PrimitiveTrainConfig `cfg` (its fields of these names), with
        `changes` on top."""
        named = {f.name: getattr(cfg, f.name) for f in fields(cls) if hasattr(cfg, f.name)}
        return cls(**{**named, **changes})

    def __post_init__(self) -> None:
        checks = {
            "gamma": 0.0 <= self.gamma <= 1.0,
            "tau": 0.0 < self.tau <= 1.0,
            "actor_lr": self.actor_lr > 0,
            "critic_lr": self.critic_lr > 0,
            "policy_delay": isinstance(self.policy_delay, int) and self.policy_delay >= 1,
            "target_noise": self.target_noise >= 0,
            "target_noise_clip": self.target_noise_clip >= 0,
            "batch_size": isinstance(self.batch_size, int) and self.batch_size >= 1,
            "grad_clip": self.grad_clip > 0,
        }
        for name, ok in checks.items():
            value = getattr(self, name)
            if not ok or (isinstance(value, float) and not math.isfinite(value)):
                raise ValueError(f"TD3Settings.{name}: invalid value {value!r}")


class TD3Learner:
    """Owns the actor, twin critic, their targets and optimisers; `select` acts, `update` learns."""

    def __init__(self, actor: nn.Module, critic: nn.Module, settings: TD3Settings,
                 device: str | torch.device = "cpu", seed: int = 0):
        self.settings = settings
        if not isinstance(self.settings, TD3Settings):
            raise ValueError(f"settings: expected TD3Settings, got {type(settings).__name__}")
        self.device = torch.device(device)
        self.actor = actor.to(self.device)
        self.critic = critic.to(self.device)
        # Targets only ever change by Polyak averaging, never by gradients.
        self.actor_target = copy.deepcopy(self.actor).requires_grad_(False)
        self.critic_target = copy.deepcopy(self.critic).requires_grad_(False)
        self.actor_optim = torch.optim.Adam(self.actor.parameters(), lr=self.settings.actor_lr)
        self.critic_optim = torch.optim.Adam(self.critic.parameters(),
                                             lr=self.settings.critic_lr)
        self.generator = torch.Generator(device=self.device)
        self.generator.manual_seed(int(seed))
        self.updates = 0
        self._last_actor_loss = math.nan

    # ----------------------------------------------------------------------------------- acting

    def _on_device(self, features: Features) -> dict[str, torch.Tensor]:
        if not isinstance(features, Mapping):
            raise ValueError(f"features: expected a dict of tensors, got "
                             f"{type(features).__name__}")
        return {k: torch.as_tensor(v, dtype=torch.float32, device=self.device)
                for k, v in features.items()}

    def _scores_and_motions(self, features: Features) -> tuple[torch.Tensor, torch.Tensor]:
        return scores_and_motions(self.actor, self.critic, self._on_device(features))

    def scores(self, features: Features) -> torch.Tensor:
        """(B, L): Q1(s, i, actor(s)_i) per location, the score the policy acts on (no grad;
        -inf at locations features["mask"] rules out)."""
        return self._scores_and_motions(features)[0]

    def select(self, features: Features, *, greedy: bool, temperature: float = 1.0,
               motion_noise: float = 0.0, rng: np.random.Generator | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The learner's networks choosing primitives: select_primitives with its actor and
        critic on its device."""
        return select_primitives(self._scores_and_motions(features), greedy=greedy,
                                 temperature=temperature, motion_noise=motion_noise, rng=rng)

    # --------------------------------------------------------------------------------- learning

    def _check_batch(self, batch: Mapping) -> tuple[dict, dict, torch.Tensor, torch.Tensor,
                                                    torch.Tensor, torch.Tensor]:
        for key in ("features", "location", "motion", "reward", "done", "next_features"):
            if key not in batch:
                raise ValueError(f"batch: missing key {key!r}")
        features = self._on_device(batch["features"])
        next_features = self._on_device(batch["next_features"])
        location = torch.as_tensor(batch["location"], device=self.device).long()
        motion = torch.as_tensor(batch["motion"], dtype=torch.float32, device=self.device)
        reward = torch.as_tensor(batch["reward"], dtype=torch.float32, device=self.device)
        done = torch.as_tensor(batch["done"], dtype=torch.float32, device=self.device)
        if location.dim() != 1 or location.shape[0] == 0:
            raise ValueError(f"batch['location']: expected shape (B,) with B >= 1, got "
                             f"{tuple(location.shape)}")
        n = location.shape[0]
        for name, value, ndim in (("location", location, 1), ("motion", motion, 2),
                                  ("reward", reward, 1), ("done", done, 1)):
            if value.dim() != ndim or value.shape[0] != n:
                raise ValueError(f"batch['{name}']: shape {tuple(value.shape)} does not fit a "
                                 f"batch of {n}")
        locations = features["tokens"].shape[1] if "tokens" in features else 0
        if (location.min() < 0 or location.max() >= locations):
            raise ValueError(f"batch['location']: indices must lie in [0, {locations})")
        return features, next_features, location, motion, reward, done

    @staticmethod
    def _at_location(features: dict[str, torch.Tensor],
                     location: torch.Tensor) -> dict[str, torch.Tensor]:
        """The features of one location per state, as a batch with L = 1: scoring only the taken
        location costs 1/L of scoring all of them."""
        rows = torch.arange(location.shape[0], device=location.device)
        picked = {}
        for key, value in features.items():
            picked[key] = value[rows, location].unsqueeze(1) if value.dim() == 3 else value
        return picked

    def update(self, batch: Mapping) -> dict[str, float]:
        """One TD3 step on `batch` (as ReplayBuffer.sample returns it)."""
        s = self.settings
        features, next_features, location, motion, reward, done = self._check_batch(batch)

        with torch.no_grad():
            next_motions = self.actor_target(next_features)
            noise = torch.randn(next_motions.shape, generator=self.generator,
                                device=self.device) * s.target_noise
            noise = noise.clamp(-s.target_noise_clip, s.target_noise_clip)
            next_motions = (next_motions + noise).clamp(-1.0, 1.0)
            q1_next, q2_next = self.critic_target(next_features, next_motions)
            # The location s' is valued at: the one the online policy would choose there (its
            # own score, among the locations it may take), valued by the targets' pessimistic
            # (clipped double-Q) estimate. Taking the max of the targets' estimates over all
            # locations instead (measured: push run, 15,000 primitives) let Q climb steadily to
            # 1.85 while the returns fell to ~0: the max over 16 noisy estimates is biased up,
            # the decoupling of choice and value (Double DQN) removes that bias.
            online_scores = masked(self.critic(next_features, self.actor(next_features))[0],
                                   next_features)
            chosen = online_scores.argmax(dim=1)
            rows = torch.arange(chosen.shape[0], device=chosen.device)
            next_value = torch.minimum(q1_next, q2_next)[rows, chosen]
            target = reward + s.gamma * (1.0 - done) * next_value

        q1, q2 = self.critic(self._at_location(features, location), motion.unsqueeze(1))
        q1, q2 = q1.squeeze(1), q2.squeeze(1)
        critic_loss = nn.functional.mse_loss(q1, target) + nn.functional.mse_loss(q2, target)
        self.critic_optim.zero_grad(set_to_none=True)
        critic_loss.backward()
        nn.utils.clip_grad_norm_(self.critic.parameters(), s.grad_clip)
        self.critic_optim.step()
        self.updates += 1

        if self.updates % s.policy_delay == 0:
            self._last_actor_loss = self._actor_step(features)
            self._soft_update(self.actor_target, self.actor)
            self._soft_update(self.critic_target, self.critic)

        return {"critic_loss": float(critic_loss.detach()),
                "actor_loss": self._last_actor_loss,
                "q_mean": float(q1.detach().mean())}

    def _actor_step(self, features: dict[str, torch.Tensor]) -> float:
        # The critic is held fixed here: no gradients into its parameters (saves the memory and
        # keeps its .grad clean for the next critic step).
        self.critic.requires_grad_(False)
        try:
            q1, _ = self.critic(features, self.actor(features))
            if "mask" in features:  # over every usable location of every state
                usable = (features["mask"] > 0.5).float()
                actor_loss = -(q1 * usable).sum() / usable.sum().clamp(min=1.0)
            else:
                actor_loss = -q1.mean()  # over every location of every state
        finally:
            self.critic.requires_grad_(True)
        self.actor_optim.zero_grad(set_to_none=True)
        actor_loss.backward()
        nn.utils.clip_grad_norm_(self.actor.parameters(), self.settings.grad_clip)
        self.actor_optim.step()
        return float(actor_loss.detach())

    @torch.no_grad()
    def _soft_update(self, target: nn.Module, online: nn.Module) -> None:
        for t, o in zip(target.parameters(), online.parameters()):
            t.lerp_(o, self.settings.tau)
        for t, o in zip(target.buffers(), online.buffers()):
            t.copy_(o)

    # ------------------------------------------------------------------------------ checkpoints

    def state_dict(self) -> dict:
        """Everything a resumed run needs to continue exactly (settings only for reference)."""
        return {
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
            "actor_target": self.actor_target.state_dict(),
            "critic_target": self.critic_target.state_dict(),
            "actor_optim": self.actor_optim.state_dict(),
            "critic_optim": self.critic_optim.state_dict(),
            "updates": self.updates,
            "last_actor_loss": self._last_actor_loss,
            "generator": self.generator.get_state(),
            "settings": asdict(self.settings),
        }

    def load_state_dict(self, state: Mapping) -> None:
        required = ("actor", "critic", "actor_target", "critic_target", "actor_optim",
                    "critic_optim", "updates")
        for key in required:
            if key not in state:
                raise ValueError(f"state: missing key {key!r}")
        # A deep copy: optimisers may keep the given tensors as their own state, and the
        # learner the state came from would otherwise keep stepping them in place.
        state = copy.deepcopy(dict(state))
        self.actor.load_state_dict(state["actor"])
        self.critic.load_state_dict(state["critic"])
        self.actor_target.load_state_dict(state["actor_target"])
        self.critic_target.load_state_dict(state["critic_target"])
        self.actor_optim.load_state_dict(state["actor_optim"])
        self.critic_optim.load_state_dict(state["critic_optim"])
        self.updates = int(state["updates"])
        self._last_actor_loss = float(state.get("last_actor_loss", math.nan))
        if "generator" in state:
            self.generator.set_state(state["generator"].cpu())

