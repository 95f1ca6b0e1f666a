"""The CORN patch-transformer encoder (pure torch): cloud + gripper pose -> 17 x 128 tokens.

Patches: 16 farthest-point centres, 32 nearest neighbours each, sorted by distance and centred.
Tokenizer: the flattened patch (96) through Linear-LN-GELU 256, Linear-LN-GELU 256, Linear 128.
Position: cat(centre (3), MLP 3 -> 128 -> 125 (GELU)) added to each patch token.
Hand token: Linear(9 -> 128) on tool position + 6D rotation, placed first.
Transformer: 2 pre-LN layers, width 128, 4 heads, feed-forward 128 (GELU), then a final LN.
Inputs are normalised points and hand position (nn/encoders/input_normalization.py; NormalizedEncoder in
nn/encoders/encoder_files.py applies the normalisation the encoder was pretrained with).
"""

from __future__ import annotations

import torch
from torch import nn

from corn_drake.contract import HAND_STATE_DIM

from corn_drake.nn.encoders.patchify import group, patch_indices


class EncoderLayer(nn.Module):
    """Pre-LN transformer block with a feed-forward width equal to the model width.

    As in the authors' ViT-MAE-style layer, the attention output passes one more Linear(D, D)
    before the residual (that makes the ~0.375 M parameters of the paper's encoder).
    """

    def __init__(self, dim: int, heads: int, ffn: int, dropout: float = 0.0):
        super().__init__()
        self.norm1 = nn.LayerNorm(dim, eps=1e-6)
        self.attn = nn.MultiheadAttention(dim, heads, dropout=dropout, batch_first=True)
        self.attn_out = nn.Linear(dim, dim)
        self.norm2 = nn.LayerNorm(dim, eps=1e-6)
        self.ffn = nn.Sequential(nn.Linear(dim, ffn), nn.GELU(), nn.Linear(ffn, dim))
        self.drop = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.norm1(x)
        x = x + self.drop(self.attn_out(self.attn(h, h, h, need_weights=False)[0]))
        return x + self.drop(self.ffn(self.norm2(x)))


class CORNEncoder(nn.Module):
    def __init__(self, num_patches: int = 16, patch_size: int = 32, dim: int = 128,
                 layers: int = 2, heads: int = 4, ffn: int = 128, hand_dim: int = HAND_STATE_DIM,
                 dropout: float = 0.0):
        super().__init__()
        self.num_patches, self.patch_size, self.dim = num_patches, patch_size, dim
        self.tokenizer = nn.Sequential(
            nn.Linear(3 * patch_size, 256), nn.LayerNorm(256), nn.GELU(),
            nn.Linear(256, 256), nn.LayerNorm(256), nn.GELU(),
            nn.Linear(256, dim))
        self.position = nn.Sequential(nn.Linear(3, 128), nn.GELU(), nn.Linear(128, dim - 3))
        self.hand = nn.Linear(hand_dim, dim)
        self.layers = nn.ModuleList(EncoderLayer(dim, heads, ffn, dropout) for _ in range(layers))
        self.norm = nn.LayerNorm(dim, eps=1e-6)

    def forward(self, points: torch.Tensor, hand: torch.Tensor, indices=None,
                extra_tokens: torch.Tensor | None = None) -> torch.Tensor:
        """points (B, N, 3), hand (B, 9) -> tokens (B, 1 + G, D), hand token first.

        `indices` = patch_indices(points) may be passed in when known (a cloud moved rigidly).
        `extra_tokens` (B, K, D), when given, enter the transformer between the hand token and
        the patch tokens (the student's task tokens): the output is then (B, 1 + K + G, D).
        """
        if hand.shape != (points.shape[0], self.hand.in_features):
            # Named here: torch would only report a matmul or cat size mismatch.
            raise ValueError(f"hand must be (B, {self.hand.in_features}) with B = "
                             f"{points.shape[0]} clouds, got {tuple(hand.shape)}")
        if extra_tokens is not None and (extra_tokens.ndim != 3 or extra_tokens.shape[2] != self.dim
                                         or extra_tokens.shape[0] != points.shape[0]):
            raise ValueError(f"extra_tokens must be (B, K, {self.dim}) with B = {points.shape[0]} "
                             f"clouds, got {tuple(extra_tokens.shape)}")
        tokens, centers = self.tokenize(points, indices)
        return self.transform(hand, tokens + self.embed_positions(centers), extra_tokens)

    def tokenize(self, points: torch.Tensor, indices=None) -> tuple[torch.Tensor, torch.Tensor]:
        """(patch tokens before the position embedding (B, G, D), patch centres (B, G, 3)).
        Split from forward so a pretext task can replace some patches' tokens (P2V-lite's mask
        token) and keep their positions."""
        center_idx, knn_idx = indices if indices is not None else patch_indices(
            points, self.num_patches, self.patch_size)
        centers, patches = group(points, center_idx, knn_idx)
        return self.tokenizer(patches.flatten(2)), centers

    def embed_positions(self, centers: torch.Tensor) -> torch.Tensor:
        """(B, G, D): the centre itself in the first 3 channels, its MLP embedding in the rest."""
        return torch.cat([centers, self.position(centers)], dim=-1)

    def transform(self, hand: torch.Tensor, tokens: torch.Tensor,
                  extra_tokens: torch.Tensor | None = None) -> torch.Tensor:
        """Hand token, extra tokens and position-embedded patch tokens through the transformer
        and the final LayerNorm -> (B, 1 + K + G, D)."""
        extra = [] if extra_tokens is None else [extra_tokens]
        x = torch.cat([self.hand(hand).unsqueeze(1), *extra, tokens], dim=1)
        for layer in self.layers:
            x = layer(x)
        return self.norm(x)


class ContactHead(nn.Module):
    """Per-patch contact logit: MLP 128 -> 128 -> 128 -> 1 on each patch token (hand skipped)."""

    def __init__(self, dim: int = 128):
        super().__init__()
        self.mlp = nn.Sequential(nn.Linear(dim, 128), nn.LayerNorm(128), nn.GELU(),
                                 nn.Linear(128, 128), nn.LayerNorm(128), nn.GELU(),
                                 nn.Linear(128, 1))

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        return self.mlp(tokens[:, 1:]).squeeze(-1)


class CORNContactModel(nn.Module):
    """Encoder + contact head; also returns the patch indices so labels can be grouped alike."""

    def __init__(self, encoder: CORNEncoder | None = None):
        super().__init__()
        self.encoder = encoder or CORNEncoder(dropout=0.01)
        self.head = ContactHead(self.encoder.dim)

    def forward(self, points: torch.Tensor, hand: torch.Tensor):
        indices = patch_indices(points, self.encoder.num_patches, self.encoder.patch_size)
        return self.head(self.encoder(points, hand, indices)), indices
