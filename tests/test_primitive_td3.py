"""The contact-primitive learner: per-location heads, the replay ring buffer and TD3.

A tiny problem with a known answer drives the learning tests: 4 candidate locations, each
marked by a fixed code in its `local` extras, and a one-step reward of motion[0] at location 2
and -0.5 anywhere else. A learner that works must fit that critic and then choose location 2
with a positive motion[0] on states it has never seen.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch

from corn_drake.config.primitive import PrimitiveTrainConfig
from corn_drake.nn.primitive_heads import (
    PrimitiveActor,
    PrimitiveCritic,
    location_features_dims,
)
from corn_drake.rl.primitive.replay import ReplayBuffer
from corn_drake.rl.primitive.td3 import TD3Learner, TD3Settings

L, D, K, G = 4, 8, 3, 5
GOOD_LOCATION = 2


def _state(rng: np.random.Generator) -> dict[str, np.ndarray]:
    # Small token/global noise: the location code in `local` and the motion carry the answer,
    # the rest is nuisance the critic must not latch onto with only 64 transitions.
    return {"tokens": (0.3 * rng.normal(size=(L, D))).astype(np.float32),
            "local": np.eye(L, K, dtype=np.float32),
            "global": (0.3 * rng.normal(size=G)).astype(np.float32)}


def _reward(location: int, motion: np.ndarray) -> float:
    return float(motion[0]) if location == GOOD_LOCATION else -0.5


def _filled_buffer(n: int = 64, capacity: int = 128, seed: int = 0) -> ReplayBuffer:
    rng = np.random.default_rng(seed)
    buffer = ReplayBuffer(capacity)
    for _ in range(n):
        location = int(rng.integers(L))
        motion = rng.uniform(-1, 1, size=3).astype(np.float32)
        buffer.add(_state(rng), location, motion, _reward(location, motion), True, _state(rng))
    return buffer


def _batched(states: list[dict[str, np.ndarray]]) -> dict[str, torch.Tensor]:
    return {k: torch.from_numpy(np.stack([s[k] for s in states])) for k in states[0]}


def _settings(**changes) -> TD3Settings:
    """A default primitive run's TD3 settings, `changes` on top."""
    return TD3Settings.for_run(PrimitiveTrainConfig(), **changes)


def _learner(seed: int = 0, settings: TD3Settings | None = None) -> TD3Learner:
    torch.manual_seed(seed)
    return TD3Learner(PrimitiveActor(D, K, G, hidden=64), PrimitiveCritic(D, K, G, hidden=64),
                      settings or _settings(), seed=seed)


@pytest.fixture(scope="module")
def trained():
    """A learner after 300 updates on the fixed replay, and its critic losses."""
    learner = _learner()
    buffer = _filled_buffer()
    rng = np.random.default_rng(1)
    losses = [learner.update(buffer.sample(64, rng))["critic_loss"] for _ in range(300)]
    return learner, losses


# ------------------------------------------------------------------------------------ learning

def test_critic_loss_falls_on_a_fixed_replay(trained):
    learner, losses = trained
    assert learner.updates == 300
    first, last = np.mean(losses[:20]), np.mean(losses[-20:])
    assert np.isfinite(losses).all()
    assert last < 0.3 * first, (first, last)


def test_greedy_policy_touches_the_rewarded_location_with_a_positive_push(trained):
    learner, _ = trained
    states = [_state(np.random.default_rng(1000 + i)) for i in range(32)]
    location, motion, scores = learner.select(_batched(states), greedy=True)
    good = (location == GOOD_LOCATION) & (motion[:, 0] > 0)
    assert good.mean() >= 0.75, (location, motion[:, 0])
    # The learned value of pushing well at location 2 beats the -0.5 elsewhere.
    assert scores[:, GOOD_LOCATION].mean() > scores[:, [0, 1, 3]].mean()


def test_update_target_is_reward_plus_discounted_min_q_where_the_online_policy_acts():
    settings = _settings(policy_delay=1000)  # no actor step: targets stay fixed
    learner = _learner(seed=3, settings=settings)
    batch = _filled_buffer(n=16, seed=3).sample(16, np.random.default_rng(0))
    batch["done"] = torch.tensor([0.0, 1.0] * 8)
    twin = copy.deepcopy(learner)  # same weights and the same noise generator state

    with torch.no_grad():
        s = settings
        next_motions = twin.actor_target(batch["next_features"])
        noise = torch.randn(next_motions.shape, generator=twin.generator) * s.target_noise
        next_motions = (next_motions + noise.clamp(-s.target_noise_clip,
                                                   s.target_noise_clip)).clamp(-1, 1)
        q1n, q2n = twin.critic_target(batch["next_features"], next_motions)
        # s' is valued where the online policy would act: its own best-scoring location.
        online, _ = twin.critic(batch["next_features"], twin.actor(batch["next_features"]))
        chosen = online.argmax(1)
        value = torch.minimum(q1n, q2n)[torch.arange(16), chosen]
        y = batch["reward"] + s.gamma * (1 - batch["done"]) * value
        # Score the taken motion at the taken location only: put it at every location.
        taken = batch["motion"][:, None, :].expand(-1, L, -1)
        q1, q2 = twin.critic(batch["features"], taken)
        rows = torch.arange(16)
        q1, q2 = q1[rows, batch["location"]], q2[rows, batch["location"]]
        expected = ((q1 - y) ** 2).mean() + ((q2 - y) ** 2).mean()

    result = learner.update(batch)
    assert result["critic_loss"] == pytest.approx(float(expected), rel=1e-5)
    assert result["q_mean"] == pytest.approx(float(q1.mean()), rel=1e-5, abs=1e-6)
    assert np.isnan(result["actor_loss"])


def test_actor_and_targets_move_only_every_policy_delay_updates():
    learner = _learner(settings=_settings(policy_delay=2))
    batch = _filled_buffer(n=8).sample(8, np.random.default_rng(0))
    actor_before = copy.deepcopy(learner.actor.state_dict())
    target_before = copy.deepcopy(learner.critic_target.state_dict())
    first = learner.update(batch)
    assert np.isnan(first["actor_loss"])
    assert all(torch.equal(v, learner.actor.state_dict()[k]) for k, v in actor_before.items())
    second = learner.update(batch)
    assert np.isfinite(second["actor_loss"])
    assert not all(torch.equal(v, learner.actor.state_dict()[k])
                   for k, v in actor_before.items())
    assert not all(torch.equal(v, learner.critic_target.state_dict()[k])
                   for k, v in target_before.items())


# -------------------------------------------------------------------------------------- acting

def test_greedy_select_is_argmax_of_scores_with_the_actors_motion():
    learner = _learner(seed=5)
    features = _batched([_state(np.random.default_rng(i)) for i in range(6)])
    location, motion, scores = learner.select(features, greedy=True)
    expected_scores = learner.scores(features).numpy()
    np.testing.assert_allclose(scores, expected_scores)
    np.testing.assert_array_equal(location, expected_scores.argmax(axis=1))
    with torch.no_grad():
        motions = learner.actor(features).numpy()
    np.testing.assert_allclose(motion, motions[np.arange(6), location])
    assert location.dtype == np.int64 and motion.dtype == np.float32 and motion.shape == (6, 3)


def test_exploring_select_repeats_with_the_same_seed():
    learner = _learner(seed=6)
    features = _batched([_state(np.random.default_rng(i)) for i in range(64)])

    def explore(seed: int):
        return learner.select(features, greedy=False, temperature=10.0, motion_noise=0.5,
                              rng=np.random.default_rng(seed))

    loc_a, motion_a, _ = explore(7)
    loc_b, motion_b, _ = explore(7)
    np.testing.assert_array_equal(loc_a, loc_b)
    np.testing.assert_array_equal(motion_a, motion_b)
    _, motion_c, _ = explore(8)
    assert not np.array_equal(motion_a, motion_c)
    # A high temperature samples locations rather than always taking the argmax.
    assert len(np.unique(loc_a)) > 1
    assert np.abs(motion_a).max() <= 1.0


def test_exploring_select_needs_rng_and_positive_temperature():
    learner = _learner()
    features = _batched([_state(np.random.default_rng(0))])
    with pytest.raises(ValueError, match="rng"):
        learner.select(features, greedy=False, temperature=1.0, motion_noise=0.1)
    with pytest.raises(ValueError, match="temperature"):
        learner.select(features, greedy=False, temperature=0.0, motion_noise=0.1,
                       rng=np.random.default_rng(0))


# -------------------------------------------------------------------------------- checkpoints

def test_learner_loaded_from_state_dict_continues_identically():
    buffer = _filled_buffer(n=32)
    rng = np.random.default_rng(2)
    original = _learner(seed=0)
    for _ in range(5):  # odd: the resumed run's next update is an actor step
        original.update(buffer.sample(16, rng))
    resumed = _learner(seed=11)  # different weights and noise until loaded
    resumed.load_state_dict(original.state_dict())
    assert resumed.updates == 5

    batches = [buffer.sample(16, rng) for _ in range(3)]
    for batch in batches:
        assert original.update(batch) == resumed.update(batch)
    for a, b in ((original.actor, resumed.actor), (original.critic_target, resumed.critic_target)):
        for (name, x), y in zip(a.state_dict().items(), b.state_dict().values()):
            assert torch.equal(x, y), name


# ------------------------------------------------------------------------------------- replay

def test_replay_save_load_gives_identical_batches(tmp_path):
    buffer = _filled_buffer(n=15, capacity=10)  # wrapped: the ring position matters
    assert len(buffer) == 10 and buffer.capacity == 10
    path = tmp_path / "replay.npz"
    buffer.save(path)
    assert [p.name for p in tmp_path.iterdir()] == ["replay.npz"]  # no temporary left
    loaded = ReplayBuffer.load(path, capacity=10)
    assert len(loaded) == 10 and loaded.capacity == 10

    extra = _state(np.random.default_rng(99))
    for b in (buffer, loaded):  # the next add must overwrite the same slot in both
        b.add(extra, 1, np.zeros(3, np.float32), 0.25, False, extra)
    a = buffer.sample(12, np.random.default_rng(4))
    b = loaded.sample(12, np.random.default_rng(4))
    for key in ("location", "motion", "reward", "done"):
        assert torch.equal(a[key], b[key]), key
    for state in ("features", "next_features"):
        for key in a[state]:
            assert torch.equal(a[state][key], b[state][key]), (state, key)
    assert a["features"]["tokens"].dtype == torch.float32 and a["location"].dtype == torch.long


def test_replay_load_into_a_larger_buffer_keeps_the_transitions_oldest_first(tmp_path):
    buffer = ReplayBuffer(3)
    state = _state(np.random.default_rng(0))
    for i in range(5):  # keeps rewards 2, 3, 4
        buffer.add(state, 0, np.zeros(3, np.float32), float(i), False, state)
    buffer.save(tmp_path / "r.npz")
    bigger = ReplayBuffer.load(tmp_path / "r.npz", capacity=5)
    bigger.add(state, 0, np.zeros(3, np.float32), 5.0, False, state)
    assert len(bigger) == 4
    np.testing.assert_array_equal(bigger._store["reward"][:4], [2, 3, 4, 5])
    with pytest.raises(ValueError, match="capacity"):
        ReplayBuffer.load(tmp_path / "r.npz", capacity=2)


def test_replay_rejects_a_shape_change_naming_the_key():
    buffer = _filled_buffer(n=2)
    rng = np.random.default_rng(0)
    good = _state(rng)
    wide = dict(good, tokens=np.zeros((L, D + 1), np.float32))
    with pytest.raises(ValueError, match="tokens"):
        buffer.add(wide, 0, np.zeros(3, np.float32), 0.0, False, good)
    bad_global = dict(good, **{"global": np.zeros(G + 2, np.float32)})
    with pytest.raises(ValueError, match="global"):
        buffer.add(good, 0, np.zeros(3, np.float32), 0.0, False, bad_global)
    with pytest.raises(ValueError, match="motion"):
        buffer.add(good, 0, np.zeros(4, np.float32), 0.0, False, good)
    with pytest.raises(ValueError, match="location"):
        buffer.add(good, L, np.zeros(3, np.float32), 0.0, False, good)
    assert len(buffer) == 2  # nothing half-written


def test_replay_stores_tokens_in_half_precision_and_refuses_empty_sampling():
    buffer = _filled_buffer(n=1)
    assert buffer._store["features/tokens"].dtype == np.float16
    assert buffer._store["features/local"].dtype == np.float32
    with pytest.raises(ValueError, match="empty"):
        ReplayBuffer(4).sample(2, np.random.default_rng(0))
    with pytest.raises(ValueError, match="capacity"):
        ReplayBuffer(0)


# -------------------------------------------------------------------------------------- heads

def test_heads_shapes_and_bad_input():
    features = _batched([_state(np.random.default_rng(i)) for i in range(2)])
    assert location_features_dims(features) == (D, K, G)
    actor, critic = PrimitiveActor(D, K, G, hidden=16), PrimitiveCritic(D, K, G, hidden=16)
    motions = actor(features)
    assert motions.shape == (2, L, 3) and motions.abs().max() <= 1
    q1, q2 = critic(features, motions)
    assert q1.shape == q2.shape == (2, L) and not torch.equal(q1, q2)
    with pytest.raises(ValueError, match="tokens"):
        actor(dict(features, tokens=features["tokens"][0]))
    with pytest.raises(ValueError, match="global"):
        actor(dict(features, **{"global": features["global"][:1]}))
    with pytest.raises(ValueError, match="motions"):
        critic(features, motions[:, :2])
    with pytest.raises(ValueError, match="policy_delay"):
        _settings(policy_delay=0)


# ------------------------------------------------------------------------------- the location mask

def _masked_state(rng, usable):
    state = _state(rng)
    state["mask"] = np.asarray(usable, np.float32)
    return state


def test_masked_locations_are_never_chosen_and_never_bootstrapped_from():
    rng = np.random.default_rng(5)
    learner = _learner(seed=5, settings=_settings(policy_delay=1000))
    usable = np.zeros(L, np.float32)
    usable[1] = 1.0  # one usable location per state
    states = [_masked_state(rng, usable) for _ in range(32)]
    batch = {k: torch.as_tensor(np.stack([s[k] for s in states])) for k in states[0]}
    scores = learner.scores(batch)
    assert torch.isinf(scores[:, [0, 2, 3]]).all() and torch.isfinite(scores[:, 1]).all()
    greedy, _, _ = learner.select(batch, greedy=True)
    sampled, _, _ = learner.select(batch, greedy=False, temperature=10.0, motion_noise=0.1,
                                   rng=np.random.default_rng(0))
    assert (greedy == 1).all() and (sampled == 1).all()
    # The target values s' at its only usable location, whatever the ruled-out locations'
    # (never trained) estimates say.
    buffer = ReplayBuffer(64)
    for s in states:
        buffer.add(s, 1, np.zeros(3, np.float32), 0.5, False, s)
    sample = buffer.sample(16, np.random.default_rng(1))
    twin = copy.deepcopy(learner)
    with torch.no_grad():
        st = twin.settings
        nxt = sample["next_features"]
        motions = twin.actor_target(nxt)
        noise = torch.randn(motions.shape, generator=twin.generator) * st.target_noise
        motions = (motions + noise.clamp(-st.target_noise_clip, st.target_noise_clip)).clamp(-1, 1)
        q1n, q2n = twin.critic_target(nxt, motions)
        y = sample["reward"] + st.gamma * torch.minimum(q1n, q2n)[:, 1]
        q1, q2 = twin.critic(twin._at_location(sample["features"], sample["location"]),
                             sample["motion"].unsqueeze(1))
        expected = ((q1.squeeze(1) - y) ** 2).mean() + ((q2.squeeze(1) - y) ** 2).mean()
    assert learner.update(sample)["critic_loss"] == pytest.approx(float(expected), rel=1e-5)


def test_a_state_with_no_usable_location_keeps_all_of_them():
    rng = np.random.default_rng(6)
    learner = _learner(seed=6)
    state = _masked_state(rng, np.zeros(L, np.float32))
    batch = {k: torch.as_tensor(v)[None] for k, v in state.items()}
    assert torch.isfinite(learner.scores(batch)).all()


def test_the_learners_numbers_are_the_run_configs():
    """TD3Settings has no numbers of its own but the gradient clip: a run's config sets them."""
    cfg = PrimitiveTrainConfig(gamma=0.8, batch_size=32, policy_delay=3)
    settings = TD3Settings.for_run(cfg)
    assert (settings.gamma, settings.batch_size, settings.policy_delay) == (0.8, 32, 3)
    assert TD3Settings.for_run(PrimitiveTrainConfig()).gamma == PrimitiveTrainConfig().gamma
    with pytest.raises(TypeError):
        TD3Settings()
