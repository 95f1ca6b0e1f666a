"""The CORN patch encoder (nn/encoders/corn_encoder.py) directly: shapes, what point and patch order do to its
tokens, and bad input.

Order behaviour, derived from the code: the patches come from patchify (FPS from point 0, kNN
sorted by distance: see tests/test_patchify.py), the tokenizer reads each patch's sorted,
centred points, and a patch token's position embedding is computed from its centre's
coordinates, not from its index. The transformer layers have no index embedding, so they are
permutation-equivariant over tokens. Hence:
- permuting the cloud's points while keeping point 0 first leaves every token unchanged;
- reordering the patches (given indices) reorders the patch tokens the same way and leaves the
  hand token unchanged;
- bringing another point first starts FPS elsewhere, so the tokens change.
"""

import numpy as np
import pytest
import torch

from corn_drake.contract import HAND_STATE_DIM
from corn_drake.nn.encoders.corn_encoder import CORNEncoder
from corn_drake.nn.encoders.patchify import patch_indices

SEED = 0


@pytest.fixture(scope="module")
def encoder():
    torch.manual_seed(SEED)
    return CORNEncoder().eval()


def _inputs(batch: int, points: int, seed: int = SEED):
    rng = np.random.default_rng(seed)
    cloud = torch.from_numpy(rng.normal(scale=0.3, size=(batch, points, 3))).float()
    hand = torch.from_numpy(rng.normal(size=(batch, HAND_STATE_DIM))).float()
    return cloud, hand


@pytest.mark.parametrize("batch, points", [(1, 32), (2, 100), (5, 512)])
def test_tokens_shape_for_batch_sizes_and_point_counts(encoder, batch, points):
    cloud, hand = _inputs(batch, points)
    with torch.no_grad():
        tokens = encoder(cloud, hand)
    assert tokens.shape == (batch, 1 + encoder.num_patches, encoder.dim)
    assert torch.isfinite(tokens).all()


def test_other_patch_counts_and_sizes_set_the_token_count():
    torch.manual_seed(SEED)
    small = CORNEncoder(num_patches=8, patch_size=16, dim=64, heads=2, ffn=64).eval()
    cloud, hand = _inputs(3, 48)
    with torch.no_grad():
        assert small(cloud, hand).shape == (3, 9, 64)


def test_given_indices_give_the_same_tokens_as_computed_ones(encoder):
    cloud, hand = _inputs(2, 256)
    with torch.no_grad():
        torch.testing.assert_close(encoder(cloud, hand, patch_indices(cloud)), encoder(cloud, hand))


def test_each_cloud_of_a_batch_is_encoded_on_its_own(encoder):
    cloud, hand = _inputs(4, 256)
    with torch.no_grad():
        together = encoder(cloud, hand)
        for b in range(4):
            torch.testing.assert_close(encoder(cloud[b:b + 1], hand[b:b + 1])[0], together[b])


def test_tokens_are_invariant_to_permuting_points_after_the_first(encoder):
    cloud, hand = _inputs(2, 512)
    perm = torch.cat([torch.zeros(1, dtype=torch.long),
                      1 + torch.randperm(511, generator=torch.Generator().manual_seed(SEED))])
    with torch.no_grad():
        torch.testing.assert_close(encoder(cloud[:, perm], hand), encoder(cloud, hand))


def test_reordering_patches_reorders_patch_tokens_and_keeps_the_hand_token(encoder):
    cloud, hand = _inputs(2, 512)
    center_idx, knn_idx = patch_indices(cloud)
    order = torch.randperm(encoder.num_patches, generator=torch.Generator().manual_seed(SEED))
    with torch.no_grad():
        tokens = encoder(cloud, hand, (center_idx, knn_idx))
        reordered = encoder(cloud, hand, (center_idx[:, order], knn_idx[:, order]))
    torch.testing.assert_close(reordered[:, 0], tokens[:, 0], rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(reordered[:, 1:], tokens[:, 1:][:, order], rtol=1e-5, atol=1e-5)


def test_another_first_point_changes_the_tokens(encoder):
    """The encoder is not invariant to every permutation: FPS starts from the first point."""
    cloud, hand = _inputs(1, 512)
    perm = torch.arange(512)
    perm[[0, 300]] = perm[[300, 0]]
    with torch.no_grad():
        moved = encoder(cloud[:, perm], hand) - encoder(cloud, hand)
    assert float(moved.abs().max()) > 1e-3


@pytest.mark.parametrize("cloud_shape, hand_shape, match", [
    ((2, 64, 2), (2, HAND_STATE_DIM), r"points must be \(B, N, 3\)"),
    ((2, 64, 3), (2, HAND_STATE_DIM - 1), rf"hand must be \(B, {HAND_STATE_DIM}\) with B = 2"),
    ((2, 64, 3), (3, HAND_STATE_DIM), rf"hand must be \(B, {HAND_STATE_DIM}\) with B = 2 clouds, got \(3,"),
    ((2, 16, 3), (2, HAND_STATE_DIM), "clouds need at least 32 points"),
])
def test_bad_input_shapes_are_named(encoder, cloud_shape, hand_shape, match):
    with pytest.raises(ValueError, match=match):
        encoder(torch.zeros(cloud_shape), torch.zeros(hand_shape))
