"""The PointNet contact head's split first layer computes the concatenated layer's function."""

import torch

from corn_drake.nn.encoders.pointnet import PointNetContactModel


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


def test_first_layer_reads_points_in_the_gripper_frame():
    """The last three input channels are R^T (p - t) of the world-frame pose, in decimetres,
    computed here independently from the quaternion (numpy) rather than the 6D rotation."""
    import numpy as np

    from corn_drake.pretraining.contact import hand9
    from corn_drake.nn.encoders.input_normalization import InputNormalization
    from corn_drake.nn.encoders.pointnet import PointNetEncoder
    from corn_drake.transforms import quat_wxyz_to_matrix

    rng = np.random.default_rng(3)
    q = rng.normal(size=(2, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    t = rng.uniform(-0.2, 0.2, (2, 3)) + [0, 0, 0.5]
    points = rng.uniform(-0.3, 0.3, (2, 16, 3)) + [0, 0, 0.5]
    norm = InputNormalization()
    hand = hand9(torch.tensor(np.concatenate([t, q], 1), dtype=torch.float32), norm)
    seen = {}
    encoder = PointNetEncoder()
    encoder.layers[0][0].register_forward_pre_hook(lambda m, inp: seen.update(x=inp[0]))
    encoder(norm.points(torch.tensor(points, dtype=torch.float32)), hand)
    R = quat_wxyz_to_matrix(q)
    expected = np.einsum("bji,bnj->bni", R, points - t[:, None]) / 0.1  # metres -> decimetres
    np.testing.assert_allclose(seen["x"][..., -3:].numpy(), expected, atol=1e-4)
