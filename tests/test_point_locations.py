"""Cloud points as the primitive policy's candidate locations (`locations: point`): which points,
which tokens they carry (checked against a brute-force nearest patch centre), a patch policy's
heads scoring them (its start for `init_from`), and the config's refusals."""

import numpy as np
import pytest
import torch

from corn_drake.config.diagram_files import load_primitive_env_config
from corn_drake.config.primitive import PrimitiveTrainConfig
from corn_drake.errors import InputError
from corn_drake.nn.patchify import farthest_point_sample
from corn_drake.nn.primitive_features import location_features, point_candidates
from corn_drake.package_data import data_dir
from corn_drake.rl.pretrained_encoders import load_encoder
from corn_drake.rl.primitive.agent import PrimitiveAgent
from corn_drake.transforms import pose9

ENCODER = data_dir("models") / "weights" / "push_corn" / "encoder.pt"


def _observations(batch: int = 2, points: int = 512, seed: int = 0) -> dict[str, np.ndarray]:
    """Primitive-env observations of a random elongated cloud on the table (numpy, batched)."""
    rng = np.random.default_rng(seed)
    cloud = rng.normal(0.0, 1.0, (batch, points, 3)) * [0.08, 0.03, 0.02] + [0.1, 0.0, 0.45]
    normals = rng.normal(size=(batch, points, 3))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.linalg.det(q)
    return {"cloud": cloud.astype(np.float32),
            "normals": (normals / np.linalg.norm(normals, axis=-1, keepdims=True)
                        ).astype(np.float32),
            "hand_state": np.tile(pose9([0.3, 0.1, 0.6], np.eye(3)), (batch, 1)
                                  ).astype(np.float32),
            "object_position": cloud.mean(axis=1).astype(np.float32),
            "goal": np.tile(pose9([0.05, -0.02, 0.0], q), (batch, 1)).astype(np.float32)}


def _torch(obs):
    return {k: torch.from_numpy(v) for k, v in obs.items()}


@pytest.fixture(scope="module")
def encoder():
    return load_encoder("corn", ENCODER)


def test_points_are_farthest_point_samples_carrying_their_nearest_patchs_token(encoder):
    obs = _observations()
    with torch.no_grad():
        points, candidates = location_features(encoder, _torch(obs), "point", 64)
        patches, centres = location_features(encoder, _torch(obs), "patch")
    np.testing.assert_array_equal(candidates.numpy(),
                                  farthest_point_sample(torch.from_numpy(obs["cloud"]), 64))
    # FPS from point 0 is greedy: its first 16 points are the encoder's 16 patch centres.
    np.testing.assert_array_equal(candidates[:, :16].numpy(), centres.numpy())
    cloud = obs["cloud"].astype(np.float64)
    for b in range(len(cloud)):
        chosen = cloud[b, candidates[b].numpy()]
        nearest = np.linalg.norm(chosen[:, None] - cloud[b, centres[b].numpy()][None],
                                 axis=-1).argmin(axis=1)
        np.testing.assert_array_equal(points["tokens"][b].numpy(),
                                      patches["tokens"][b, nearest].numpy())
        np.testing.assert_allclose(points["local"][b, :, :3].numpy(),
                                   (chosen - obs["object_position"][b]) * 10.0, atol=1e-5)
        np.testing.assert_allclose(points["local"][b, :, 6:].numpy(),
                                   obs["normals"][b, candidates[b].numpy()], atol=1e-7)
    np.testing.assert_array_equal(points["global"].numpy(), patches["global"].numpy())
    # At the cloud's size every point is a location, in cloud order.
    _, every = location_features(encoder, _torch(obs), "point", 512)
    np.testing.assert_array_equal(every.numpy(), np.tile(np.arange(512), (2, 1)))


@pytest.mark.parametrize("count", [0, 513])
def test_a_point_count_outside_the_cloud_is_refused(count):
    with pytest.raises(ValueError, match=f"point_count must be in \\[1, 512\\].*got {count}"):
        point_candidates(torch.zeros(1, 512, 3), count)


def test_a_patch_policys_heads_score_the_patch_centres_among_the_points_alike(encoder):
    torch.manual_seed(0)
    patch = PrimitiveAgent(encoder, "patch").eval()
    point = PrimitiveAgent(encoder, "point", point_locations=64).eval()
    with pytest.raises(InputError, match="locations 'patch', hidden 256, not locations 64 "
                                         "points, hidden 256"):
        point.load_network_state(patch.network_state(), "the patch run")
    point.load_network_state(patch.network_state(), "the patch run", heads_only=True)
    obs = _observations(seed=1)
    # A mask from the table would differ by point; score every location of both alike.
    scored = []
    for agent in (patch, point):
        features, candidates = agent.features(obs)
        features["mask"] = torch.ones_like(features["mask"])
        scored.append((agent.scores_and_motions(features), candidates))
    (patch_scores, patch_motions), centres = scored[0]
    (point_scores, point_motions), candidates = scored[1]
    assert point_scores.shape == (2, 64)
    np.testing.assert_array_equal(candidates[:, :16].numpy(), centres.numpy())
    np.testing.assert_allclose(point_scores[:, :16].numpy(), patch_scores.numpy(), atol=1e-5)
    np.testing.assert_allclose(point_motions[:, :16].numpy(), patch_motions.numpy(), atol=1e-5)
    # Another width is refused even for the heads alone.
    narrow = PrimitiveAgent(encoder, "point", hidden=64)
    with pytest.raises(InputError, match="hidden 256, not locations 64 points, hidden 64"):
        narrow.load_network_state(patch.network_state(), "the patch run", heads_only=True)


def test_a_point_agent_chooses_one_of_its_candidates(encoder):
    torch.manual_seed(0)
    agent = PrimitiveAgent(encoder, "point", point_locations=32).eval()
    obs = {k: v[0] for k, v in _observations().items()}
    choice = agent.choose(obs)
    assert len(choice["scores"]) == len(choice["candidates"]) == 32
    assert choice["point"] == choice["candidates"][choice["location"]]
    assert agent.location_count(512) == 32
    assert choice["location"] == int(np.argmax(np.where(choice["usable"], choice["scores"],
                                                        -np.inf)))


def test_more_point_locations_than_cloud_points_are_refused():
    cfg = PrimitiveTrainConfig(env=load_primitive_env_config("push"), locations="point",
                               point_locations=600)
    with pytest.raises(InputError, match="point_locations \\(600\\) must not exceed the "
                                         "cloud's 512 points"):
        cfg.check()
    with pytest.raises(InputError, match="point_locations"):
        PrimitiveTrainConfig(env=load_primitive_env_config("push"), locations="point",
                             point_locations=0).check()
