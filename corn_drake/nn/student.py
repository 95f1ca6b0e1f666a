"""The student policy (pure torch): partial cloud + proprioception + goal sequence -> Gaussian actions.

Per step (the paper's appendix, the authors' student network):
  * the teacher's patch encoder (FPS/kNN patches, MLP tokeniser, position embedding, hand token,
    2-layer transformer), with one more token per remaining student observation (TOKEN_KEYS:
    goal, joint state, previous action; each a Linear to 128 on its standardised value) placed
    after the hand token, so the transformer reads
        [hand, goal, robot_state, previous_action, 16 patches]   (1 + 3 + 16 tokens of 128);
  * 4 learned query tokens cross-attend (4 heads) over those tokens -> 4 x 128 = 512 features.
    The teacher derives its queries from the context; the student's context is already inside
    the tokens, so its queries are plain parameters;
  * a 2-layer GRU (hidden 128) over the per-step features integrates the partial views;
  * actor MLP 128 -> 128 -> 64 -> 20 (the authors' student maps its GRU state to a 128-d
    "teacher state" that the teacher's 64 -> 20 actor reads; here the same layers are one MLP),
    Gaussian with a learned state-independent log-std, like the teacher's: DAgger's KL to the
    teacher's Gaussian is then matched exactly by a constant std. No critic (DAgger needs none).

The recurrence: `starts` (B, T) marks steps at which an episode begins; the hidden state of that
batch entry is set to zero before the step. Carrying `hidden` from one call to the next is the
same as one call over the joined sequence, which is what truncated BPTT (windows of 8 steps,
hidden state detached between windows) and the evaluation LeafSystem (one step per call) rely on.

Standardisation: cloud and hand position go through the encoder's InputNormalization (the one it
was pretrained with); the token inputs through fixed mean/std buffers (identity until set, e.g.
from the teacher's running context statistics with set_token_statistics_from_context). All are
buffers, so a student's state_dict carries them.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import nn

from corn_drake.config.choices import STUDENT_PARAMETER_GROUPS, STUDENT_PRETRAINED_GROUPS
from corn_drake.contract import (ACTION_DIM, CONTEXT_KEYS, POSITION_DIM, STUDENT_OBS_KEYS,
                                 observation_size)
from corn_drake.nn.encoders.corn_encoder import CORNEncoder
from corn_drake.nn.encoders.encoder_files import NormalizedEncoder, make_policy_encoder
from corn_drake.nn.policy import mlp

# The cloud becomes patch tokens and the hand state the pretrained hand token; every other
# student observation gets a token of its own (a new contract key would join automatically).
TOKEN_KEYS = tuple(k for k in STUDENT_OBS_KEYS if k not in ("cloud", "hand_state"))

# Parameter groups, for freezing and for saying what DAgger trains. The first three come from
# the contact-pretrained encoder (student_io.student_from_encoder copies them).
# (config/choices.py holds them: DistillConfig.frozen is checked against them.)
PRETRAINED_GROUPS = STUDENT_PRETRAINED_GROUPS
PARAMETER_GROUPS = STUDENT_PARAMETER_GROUPS


class StudentOutput(NamedTuple):
    mean: torch.Tensor      # (B, T, A) action mean (normalised action, unclipped)
    log_std: torch.Tensor   # (A,) state-independent
    hidden: torch.Tensor    # (layers, B, H) GRU state after the last step


class TokenStandardizer(nn.Module):
    """(x - mean) / std, clipped to +-clip like the teacher's context normaliser; fixed buffers
    (identity until set) so that the student's inputs do not drift while it is distilled."""

    def __init__(self, size: int, clip: float = 10.0):
        super().__init__()
        self.clip = clip
        self.register_buffer("mean", torch.zeros(size))
        self.register_buffer("std", torch.ones(size))

    def set(self, mean: torch.Tensor, var: torch.Tensor) -> None:
        mean, var = torch.as_tensor(mean).reshape(-1), torch.as_tensor(var).reshape(-1)
        if mean.shape != self.mean.shape or var.shape != self.std.shape:
            raise ValueError(f"token statistics must have {self.mean.numel()} entries, got mean "
                             f"{tuple(mean.shape)} and var {tuple(var.shape)}")
        if not (torch.isfinite(mean).all() and torch.isfinite(var).all() and (var >= 0).all()):
            raise ValueError("token statistics must be finite with var >= 0")
        self.mean.copy_(mean.to(self.mean))
        self.std.copy_(torch.sqrt(var.to(self.std) + 1e-8))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return ((x - self.mean) / self.std).clamp(-self.clip, self.clip)


class StudentPolicy(nn.Module):
    def __init__(self, encoder: NormalizedEncoder | None = None, num_queries: int = 4,
                 heads: int = 4, gru_hidden: int = 128, gru_layers: int = 2,
                 action_dim: int = ACTION_DIM):
        super().__init__()
        encoder = encoder if encoder is not None else make_policy_encoder("corn")
        if not isinstance(encoder, NormalizedEncoder) or not isinstance(encoder.network, CORNEncoder):
            # The student adds tokens to the patch transformer: only the CORN encoder has one.
            raise TypeError("the student needs a NormalizedEncoder around a CORNEncoder, got "
                            f"{type(getattr(encoder, 'network', encoder)).__name__}")
        self.encoder = encoder
        dim = encoder.network.dim
        self.token_sizes = {k: observation_size(k) for k in TOKEN_KEYS}
        self.token_standardizer = TokenStandardizer(sum(self.token_sizes.values()))
        self.tokens = nn.ModuleDict({k: nn.Linear(n, dim) for k, n in self.token_sizes.items()})
        self.queries = nn.Parameter(torch.randn(num_queries, dim) * 0.02)
        self.attention = nn.MultiheadAttention(dim, heads, batch_first=True)
        self.gru = nn.GRU(num_queries * dim, gru_hidden, num_layers=gru_layers, batch_first=True)
        self.actor = mlp([gru_hidden, 128, 64, action_dim], final_activation=False)
        self.log_std = nn.Parameter(torch.zeros(action_dim))

    # --- recurrence --------------------------------------------------------------------------
    def initial_state(self, batch: int) -> torch.Tensor:
        """The GRU state at an episode start: zeros (layers, batch, hidden)."""
        return self.log_std.new_zeros(self.gru.num_layers, batch, self.gru.hidden_size)

    def forward(self, obs: dict[str, torch.Tensor], hidden: torch.Tensor | None = None,
                starts: torch.Tensor | None = None) -> StudentOutput:
        """obs: each student key (B, T, ...) (cloud (B, T, N, 3) or flattened (B, T, 3N));
        hidden: (layers, B, H) carried from the previous call, None = episode start;
        starts: (B, T) bool, True where an episode begins (hidden reset before that step)."""
        batch, steps = self._check(obs, hidden, starts)
        features = self.step_features(obs).view(batch, steps, -1)
        h = self.initial_state(batch) if hidden is None else hidden
        if starts is None:
            out, h = self.gru(features, h)
        else:
            out, h = self._gru_with_resets(features, h, starts.to(torch.bool))
        return StudentOutput(self.actor(out), self.log_std, h)

    def _gru_with_resets(self, x, h, starts):
        # One GRU call per stretch between steps where some entry restarts (usually none or one
        # per 8-step window), zeroing the restarting entries' state at each stretch's first step.
        keep = (~starts).to(x.dtype).t().unsqueeze(-1)  # (T, B, 1), broadcasts over layers
        cuts = (starts[:, 1:].any(dim=0).nonzero().flatten() + 1).tolist()
        outputs = []
        for a, b in zip([0, *cuts], [*cuts, x.shape[1]]):
            out, h = self.gru(x[:, a:b], h * keep[a])
            outputs.append(out)
        return torch.cat(outputs, dim=1), h

    @torch.no_grad()
    def step(self, obs: dict[str, torch.Tensor], hidden: torch.Tensor | None = None
             ) -> tuple[torch.Tensor, torch.Tensor]:
        """One policy step for rollouts and the evaluation LeafSystem (no gradients): obs keys
        (B, ...) without a time axis, hidden None at an episode start -> (mean (B, A), hidden)."""
        out = self({k: v.unsqueeze(1) for k, v in obs.items()}, hidden)
        return out.mean[:, 0], out.hidden

    # --- per-step features -------------------------------------------------------------------
    def step_features(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """(B*T, Q*D) attended features of every step, independent of the other steps."""
        batch, steps = obs["hand_state"].shape[:2]
        flat = {k: obs[k].reshape(batch * steps, -1) for k in ("hand_state", *TOKEN_KEYS)}
        cloud = obs["cloud"].reshape(batch * steps, -1, POSITION_DIM)
        values = self.token_standardizer(torch.cat([flat[k] for k in TOKEN_KEYS], dim=-1))
        chunks = values.split(list(self.token_sizes.values()), dim=-1)
        extra = torch.stack([self.tokens[k](c) for k, c in zip(TOKEN_KEYS, chunks)], dim=1)
        tokens = self.encoder(cloud, flat["hand_state"], extra_tokens=extra)
        queries = self.queries.expand(tokens.shape[0], -1, -1)
        attended, _ = self.attention(queries, tokens, tokens, need_weights=False)
        return attended.flatten(1)

    def _check(self, obs, hidden, starts) -> tuple[int, int]:
        missing = [k for k in ("cloud", "hand_state", *TOKEN_KEYS) if k not in obs]
        if missing:
            raise KeyError(f"student observation lacks {missing} (needs {STUDENT_OBS_KEYS})")
        batch, steps = obs["hand_state"].shape[:2] if obs["hand_state"].ndim == 3 else (None, None)
        for k in ("hand_state", *TOKEN_KEYS):
            if obs[k].shape != (batch, steps, observation_size(k)):
                raise ValueError(f"student observation {k!r} must be (B, T, {observation_size(k)}) "
                                 f"like hand_state, got {tuple(obs[k].shape)}")
        cloud = obs["cloud"]
        if (cloud.ndim < 3 or cloud.shape[:2] != (batch, steps)
                or math.prod(cloud.shape[2:]) % POSITION_DIM):
            raise ValueError(f"student observation 'cloud' must be (B={batch}, T={steps}, N, 3) or "
                             f"(B, T, 3N), got {tuple(cloud.shape)}")
        if hidden is not None and hidden.shape != (self.gru.num_layers, batch, self.gru.hidden_size):
            raise ValueError(f"hidden must be ({self.gru.num_layers}, {batch}, "
                             f"{self.gru.hidden_size}), got {tuple(hidden.shape)}")
        if starts is not None and starts.shape != (batch, steps):
            raise ValueError(f"starts must be (B={batch}, T={steps}), got {tuple(starts.shape)}")
        return batch, steps

    # --- inputs' statistics and parameter groups ---------------------------------------------
    def set_token_statistics_from_context(self, mean: torch.Tensor, var: torch.Tensor) -> None:
        """Standardise the token inputs as the teacher standardises the same keys: `mean` and
        `var` are over the teacher's context (contract.CONTEXT_KEYS concatenated, e.g. its
        RunningMeanStd buffers); the entries of TOKEN_KEYS are picked out of them."""
        offsets, start = {}, 0
        for k in CONTEXT_KEYS:
            offsets[k] = slice(start, start + observation_size(k))
            start += observation_size(k)
        mean, var = torch.as_tensor(mean).reshape(-1), torch.as_tensor(var).reshape(-1)
        if mean.numel() != start or var.numel() != start:
            raise ValueError(f"context statistics must have {start} entries "
                             f"({' + '.join(CONTEXT_KEYS)}), got {mean.numel()} and {var.numel()}")
        self.token_standardizer.set(torch.cat([mean[offsets[k]] for k in TOKEN_KEYS]),
                                    torch.cat([var[offsets[k]] for k in TOKEN_KEYS]))

    def parameter_groups(self) -> dict[str, list[nn.Parameter]]:
        """Every parameter, once, under one of PARAMETER_GROUPS."""
        net = self.encoder.network
        modules = {"patch_tokenizer": [net.tokenizer, net.position], "hand_token": [net.hand],
                   "transformer": [net.layers, net.norm], "task_tokens": [self.tokens],
                   "cross_attention": [self.attention], "gru": [self.gru], "actor": [self.actor]}
        groups = {g: [p for m in ms for p in m.parameters()] for g, ms in modules.items()}
        groups["cross_attention"].append(self.queries)
        groups["actor"].append(self.log_std)
        return groups

    def set_frozen(self, frozen: tuple[str, ...] | list[str] = ()) -> None:
        """Trains every group except those named in `frozen` (unknown names: ValueError)."""
        unknown = sorted(set(frozen) - set(PARAMETER_GROUPS))
        if unknown:
            raise ValueError(f"unknown student parameter groups {unknown}; "
                             f"expected some of {PARAMETER_GROUPS}")
        for group, params in self.parameter_groups().items():
            for p in params:
                p.requires_grad_(group not in frozen)

    def trainable_summary(self) -> dict[str, dict]:
        """{group: {"parameters": count, "trainable": bool}} (a group is trainable when any of
        its parameters requires grad)."""
        return {g: {"parameters": sum(p.numel() for p in ps),
                    "trainable": any(p.requires_grad for p in ps)}
                for g, ps in self.parameter_groups().items()}
