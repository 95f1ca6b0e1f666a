"""Patchify (nn/encoders/patchify.py): farthest-point centres, sorted kNN groups.

What the design promises about point order, derived from the code: FPS starts at point 0 and
then always takes the point farthest from the centres chosen so far, and kNN returns each
centre's neighbours sorted by distance. Both depend on the cloud as a set of points plus which
point comes first. So a permutation that keeps point 0 in place changes nothing in the
patches' coordinates (the indices move with the points: equivariance), while a permutation
that brings another point to the front starts FPS elsewhere and gives other centres: the
patches are not invariant to every permutation, and the tests pin both facts.
"""

import numpy as np
import pytest
import torch

from corn_drake.nn.encoders.patchify import (farthest_point_sample, gather_points, group,
                                             patch_indices)

SEED = 0


def _clouds(batch: int, points: int, seed: int = SEED) -> torch.Tensor:
    # Random continuous coordinates: no two distances tie, so every argmax/topk is unique.
    return torch.from_numpy(np.random.default_rng(seed).normal(size=(batch, points, 3))).float()


def _fps_reference(cloud: np.ndarray, count: int) -> list[int]:
    """Farthest-point sampling written out from its definition, for one cloud."""
    chosen = [0]
    while len(chosen) < count:
        to_chosen = np.linalg.norm(cloud[:, None] - cloud[chosen][None], axis=-1).min(axis=1)
        chosen.append(int(to_chosen.argmax()))
    return chosen


@pytest.mark.parametrize("batch, points", [(1, 32), (2, 100), (4, 512)])
def test_shapes_for_batch_sizes_and_point_counts(batch, points):
    cloud = _clouds(batch, points)
    center_idx, knn_idx = patch_indices(cloud)
    assert center_idx.shape == (batch, 16) and knn_idx.shape == (batch, 16, 32)
    centers, patches = group(cloud, center_idx, knn_idx)
    assert centers.shape == (batch, 16, 3) and patches.shape == (batch, 16, 32, 3)
    assert int(knn_idx.max()) < points and int(knn_idx.min()) >= 0
    center_idx, knn_idx = patch_indices(cloud, num_patches=8, patch_size=16)
    assert center_idx.shape == (batch, 8) and knn_idx.shape == (batch, 8, 16)


def test_farthest_point_sample_matches_its_definition():
    cloud = _clouds(3, 200)
    idx = farthest_point_sample(cloud, 16)
    for b in range(3):
        assert idx[b].tolist() == _fps_reference(cloud[b].numpy(), 16)
        assert len(set(idx[b].tolist())) == 16  # distinct centres


def test_knn_groups_are_the_nearest_points_nearest_first_centred_on_their_centre():
    cloud = _clouds(2, 150)
    center_idx, knn_idx = patch_indices(cloud, num_patches=16, patch_size=32)
    centers, patches = group(cloud, center_idx, knn_idx)
    for b in range(2):
        distances = torch.cdist(centers[b], cloud[b])  # (G, N)
        expected = distances.sort(dim=1).values[:, :32]
        got = torch.gather(distances, 1, knn_idx[b])
        torch.testing.assert_close(got, expected)
    # The centre is its own nearest neighbour: every patch starts at its origin.
    assert torch.equal(knn_idx[:, :, 0], center_idx)
    assert float(patches[:, :, 0].abs().max()) == 0.0
    torch.testing.assert_close(patches + centers.unsqueeze(2), gather_points(cloud, knn_idx))


def test_a_batch_is_patchified_cloud_by_cloud():
    cloud = _clouds(4, 128)
    center_idx, knn_idx = patch_indices(cloud)
    for b in range(4):
        alone = patch_indices(cloud[b:b + 1])
        assert torch.equal(alone[0][0], center_idx[b]) and torch.equal(alone[1][0], knn_idx[b])


def test_permuting_points_after_the_first_moves_indices_with_the_points():
    """Equivariant indices, invariant patches: FPS and kNN see the same set and start point."""
    cloud = _clouds(2, 256)
    perm = torch.cat([torch.zeros(1, dtype=torch.long),
                      1 + torch.randperm(255, generator=torch.Generator().manual_seed(SEED))])
    shuffled = cloud[:, perm]
    center_idx, knn_idx = patch_indices(cloud)
    center_s, knn_s = patch_indices(shuffled)
    # Index i of the shuffled cloud is point perm[i] of the original.
    assert torch.equal(perm[center_s], center_idx) and torch.equal(perm[knn_s], knn_idx)
    centers, patches = group(cloud, center_idx, knn_idx)
    centers_s, patches_s = group(shuffled, center_s, knn_s)
    assert torch.equal(centers_s, centers) and torch.equal(patches_s, patches)


def test_bringing_another_point_first_changes_the_centres():
    """Not invariant to every permutation: FPS starts from whichever point is first."""
    cloud = _clouds(1, 256)
    perm = torch.arange(256)
    perm[[0, 100]] = perm[[100, 0]]  # point 100 goes first
    centers = gather_points(cloud, patch_indices(cloud)[0])
    centers_s = gather_points(cloud[:, perm], patch_indices(cloud[:, perm])[0])
    assert torch.equal(centers_s[0, 0], cloud[0, 100])
    same = torch.cdist(centers_s[0], centers[0]).min(dim=1).values == 0
    assert not bool(same.all())  # some centres are other points


@pytest.mark.parametrize("shape, match", [
    ((2, 64, 2), r"points must be \(B, N, 3\), got \(2, 64, 2\)"),
    ((64, 3), r"points must be \(B, N, 3\), got \(64, 3\)"),
    ((2, 20, 3), "clouds need at least 32 points .* got 20"),
])
def test_bad_input_shapes_are_named(shape, match):
    with pytest.raises(ValueError, match=match):
        patch_indices(torch.zeros(shape))


def test_more_centres_than_points_is_refused_not_repeated():
    with pytest.raises(ValueError, match="at least 40 points .*40 patches of 8.* got 36"):
        patch_indices(_clouds(1, 36), num_patches=40, patch_size=8)

