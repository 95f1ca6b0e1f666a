"""The PointNet contact head's split first layer computes the concatenated layer's function."""

import torch

from corn_drake.nn.pointnet import PointNetContactModel


def test_split_head_matches_concatenated_head():
    torch.manual_seed(0)
    model = PointNetContactModel()
    points, hand = torch.randn(4, 64, 3), torch.randn(4, 9)
    first, pooled = model.encoder.point_features(points, hand)
    # Reference: every point reads [its feature, the cloud's global feature] through the head.
    x = torch.cat([first, pooled.unsqueeze(1).expand(-1, points.shape[1], -1)], dim=-1)
    expected = model.head(x).squeeze(-1)
    got = model(points, hand)
    assert got.shape == (4, 64)
    torch.testing.assert_close(got, expected, atol=1e-5, rtol=1e-5)
    # Gradients reach both halves of the first head layer.
    got.sum().backward()
    w = model.head[0].weight.grad
    assert w[:, :first.shape[-1]].abs().sum() > 0 and w[:, first.shape[-1]:].abs().sum() > 0
