"""TeacherAgent: observation dict -> (action mean, value), for every policy variant.

Variants (the paper's names, corn_drake/rl/policy_kinds.py): `corn` — frozen contact-pretrained patch
encoder + cross-attention head; `e2e` — the same encoder randomly initialised and trained by PPO;
`p2v-lite` / `rot` — the same encoder pretrained on a pretext task (pretext/), frozen, with the
same cross-attention head as `corn`; `pn` — a frozen pretrained PointNet's global feature + MLP
head; `state` — no cloud, the object's bounding-box keypoints and the hand pose + MLP head.
Cloud and hand pose are normalised by the encoder itself (NormalizedEncoder, with the
normalisation it was pretrained with); the `state` variant normalises keypoints and hand pose
with the default encoder normalisation. The context (the contract's CONTEXT_KEYS,
concatenated) is normalised by a running mean/std whose buffers are part of the agent's
state_dict, so checkpoints carry them.

With `separate_critic` the value comes from `critic_head`, a second head of the same shape on the
same features (detached: the critic never trains the `e2e` encoder), instead of the actor's trunk
(PPOConfig.separate_critic says why).

The cross-attention policies (`corn`, `e2e`, `p2v-lite`, `rot`) can also say what they attended
to when they chose an action: act_and_attend returns the action and the cross-attention as
per-patch scores (nn/attention.py documents the normalisation) from the same forward pass;
`state` and `pn` have no attention and refuse.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import torch
from torch import nn

from corn_drake.config.training import PPOConfig
from corn_drake.contract import CONTEXT_DIM, CONTEXT_KEYS, POSITION_DIM, STATE_FEATURE_DIM
from corn_drake.errors import InputError, load_error_detail
from corn_drake.nn.attention import PatchAttention, nearest_patch, patch_scores
from corn_drake.nn.encoders.encoder_files import NormalizedEncoder
from corn_drake.nn.encoders.input_normalization import InputNormalization
from corn_drake.nn.encoders.patchify import patch_indices
from corn_drake.nn.policy import CrossAttentionActorCritic, MLPActorCritic, gaussian_action
from corn_drake.rl.policy_kinds import FROZEN_ENCODER_POLICIES, POLICY_KINDS, TOKEN_POLICIES
from corn_drake.rl.normalization import RunningMeanStd

# The variants whose head cross-attends over the encoder's patch tokens.
ATTENTION_KINDS = TOKEN_POLICIES

# An encoder maps (world-frame cloud (B, N, 3), hand state (B, 9)) to tokens (B, T, D) for
# the patch-encoder policies (TOKEN_POLICIES), or to a global feature (B, F) for `pn`
# (nn/encoder_io.NormalizedEncoder).
Encoder = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


def obs_to_tensors(obs: dict[str, np.ndarray], device: torch.device | str | None = None
                   ) -> dict[str, torch.Tensor]:
    """Batched numpy observations -> float32 tensors on `device` (default: the CPU), with the
    context assembled."""
    t = {k: torch.as_tensor(np.asarray(v), dtype=torch.float32, device=device)
         for k, v in obs.items()}
    t["context"] = torch.cat([t[k] for k in CONTEXT_KEYS], dim=-1)
    return t


class TeacherAgent(nn.Module):
    def __init__(self, kind: str, encoder: nn.Module | None = None, feature_dim: int | None = None,
                 separate_critic: bool = PPOConfig.separate_critic):
        super().__init__()
        if kind not in POLICY_KINDS:
            raise ValueError(f"policy must be one of {POLICY_KINDS}, got {kind!r}")
        if kind != "state" and encoder is None:
            raise ValueError(f"policy {kind!r} needs an encoder")
        if encoder is not None and not isinstance(encoder, NormalizedEncoder):
            # A bare network would get world-frame points: wrong inputs, no error anywhere.
            raise TypeError(f"policy {kind!r}: the encoder must be a NormalizedEncoder (the "
                            f"network with its input normalisation), got {type(encoder).__name__}")
        self.kind = kind
        self.encoder = encoder
        if encoder is not None and self.frozen_encoder:
            encoder.eval()
            for p in encoder.parameters():
                p.requires_grad_(False)
        self.head = self._make_head(kind, feature_dim)
        # Only its value output is used; its unused actor layers cost a few k multiply-adds.
        self.critic_head = self._make_head(kind, feature_dim) if separate_critic else None
        if kind == "state":
            # No encoder: keypoints and hand pose on the scale the encoders see.
            self.state_normalization = InputNormalization()
        self.log_std = self.head.log_std
        self.context_normalizer = RunningMeanStd((CONTEXT_DIM,))

    @staticmethod
    def _make_head(kind: str, feature_dim: int | None) -> nn.Module:
        if kind in TOKEN_POLICIES:
            return CrossAttentionActorCritic()
        if kind == "pn":
            return MLPActorCritic(feature_dim or 1024)
        return MLPActorCritic(STATE_FEATURE_DIM)

    def critic_parameters(self) -> list[nn.Parameter]:
        """The separate critic's trainable parameters ([] when the critic shares the trunk)."""
        return [] if self.critic_head is None else list(self.critic_head.parameters())

    def actor_parameters(self) -> list[nn.Parameter]:
        """Every other trainable parameter (all of them with a shared critic)."""
        critic = {id(p) for p in self.critic_parameters()}
        return [p for p in self.parameters() if p.requires_grad and id(p) not in critic]

    @property
    def frozen_encoder(self) -> bool:
        """True for corn / pn / p2v-lite / rot: PPO never trains the encoder, so its features can
        be cached."""
        return self.kind in FROZEN_ENCODER_POLICIES

    def load_saved_state(self, state: dict, source) -> None:
        """Loads a state_dict saved from an agent of this kind; one that does not fit (another
        policy, or a checkpoint written before the context normaliser and the encoder's input
        normalisation became part of the agent) is an InputError naming `source`."""
        try:
            self.load_state_dict(state)
        except RuntimeError as e:
            raise InputError(f"{source}: the saved {self.kind!r} agent does not fit this version "
                             f"({load_error_detail(e)}); checkpoints written before the agent "
                             "carried its normalisers cannot be loaded: train the run again") from None

    def update_normalizer(self, context: torch.Tensor) -> None:
        self.context_normalizer.update(context)

    def normalized_context(self, context: torch.Tensor) -> torch.Tensor:
        return self.context_normalizer.normalize(context)

    def features(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        if self.kind == "state":
            # The hand pose too: the cloud policies see it through the encoder's hand token, and
            # without it the state policy would have to learn the arm's kinematics from joints.
            norm = self.state_normalization
            keypoints = obs["object_keypoints"]
            keypoints = norm.points(keypoints.reshape(*keypoints.shape[:-1], -1, POSITION_DIM))
            return torch.cat([keypoints.flatten(-2), norm.hand(obs["hand_state"])], dim=-1)
        if self.frozen_encoder and "features" in obs:
            # Precomputed at collection time (rl/training/ppo_trainer.py): a frozen encoder
            # would give the same features again, and skipping it makes every PPO epoch much cheaper.
            return obs["features"]
        if self.kind == "e2e":
            return self.encoder(obs["cloud"], obs["hand_state"])
        with torch.no_grad():  # frozen: PPO never backpropagates into the encoder
            return self.encoder(obs["cloud"], obs["hand_state"])

    def forward(self, obs: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        features, context = self.features(obs), self.normalized_context(obs["context"])
        mu, value = self.head(features, context)
        if self.critic_head is not None:
            value = self.critic_head(features.detach(), context)[1]
        return mu, value

    def act(self, obs: dict[str, np.ndarray], unit_noise: np.ndarray | None = None) -> np.ndarray:
        """Action clipped to [-1, 1], for one or many observations: the Gaussian mean, or with
        `unit_noise` (N(0, 1) draws shaped like the action) the policy's sample
        mean + exp(log_std) * unit_noise. Pure: the same inputs give the same action, and the
        noise comes from the caller (PolicySystem's RandomSource input)."""
        single, batch = _as_batch(obs)
        with torch.no_grad():
            mu, _ = self(obs_to_tensors(batch, self.log_std.device))
        action = self._sample(mu, unit_noise)
        return action[0] if single else action

    @property
    def has_attention(self) -> bool:
        """Whether the policy cross-attends over patches (TOKEN_POLICIES: corn, e2e, p2v-lite,
        rot), so act_and_attend works."""
        return self.kind in ATTENTION_KINDS

    def act_and_attend(self, obs: dict[str, np.ndarray], unit_noise: np.ndarray | None = None
                       ) -> tuple[np.ndarray, PatchAttention]:
        """act(obs, unit_noise) and, from the same forward pass, the attention behind it: the
        cross-attention weights as per-patch scores and each cloud point's patch
        (nn/attention.PatchAttention; batched like the observation)."""
        if not self.has_attention:
            raise InputError(f"policy {self.kind!r} has no cross-attention over patches (only "
                             f"{', '.join(ATTENTION_KINDS)} have one): no attention to show")
        single, batch = _as_batch(obs)
        t = obs_to_tensors(batch, self.log_std.device)
        norm, network = self.encoder.normalization, self.encoder.network
        with torch.no_grad():
            # The patches computed here are handed to the encoder, so the scores are over
            # exactly the patches it tokenised (it would compute the same ones from the same
            # normalised points).
            points = norm.points(t["cloud"])
            indices = patch_indices(points, network.num_patches, network.patch_size)
            tokens = self.encoder(t["cloud"], t["hand_state"], indices)
            mu, _, weights = self.head.forward_with_weights(
                tokens, self.normalized_context(t["context"]))
            scores, hand = patch_scores(weights)
            point_patch = nearest_patch(points, indices[0])
        attention = PatchAttention(scores.cpu().numpy().astype(np.float64),
                                   hand.cpu().numpy().astype(np.float64),
                                   point_patch.cpu().numpy())
        action = self._sample(mu, unit_noise)
        return (action[0], attention.select(0)) if single else (action, attention)

    def attention(self, obs: dict[str, np.ndarray]) -> PatchAttention:
        """The attention of act_and_attend(obs) alone."""
        return self.act_and_attend(obs)[1]

    def _sample(self, mu: torch.Tensor, unit_noise: np.ndarray | None) -> np.ndarray:
        """The mean `mu`, or mean + exp(log_std) * unit_noise, clipped to [-1, 1], in numpy."""
        noise = None if unit_noise is None else torch.as_tensor(np.asarray(unit_noise))
        with torch.no_grad():
            return gaussian_action(mu, self.log_std, noise).cpu().numpy().astype(np.float64)


def _as_batch(obs: dict[str, np.ndarray]) -> tuple[bool, dict[str, np.ndarray]]:
    """(whether `obs` is a single observation, `obs` with a batch axis)."""
    single = np.asarray(obs["goal"]).ndim == 1
    return single, ({k: np.asarray(v)[None] for k, v in obs.items()} if single else obs)
