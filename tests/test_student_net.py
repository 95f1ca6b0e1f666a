"""The student network (nn/student.py, nn/student_io.py): shapes, the GRU state carried across
calls and reset at episode starts, what truncated BPTT's gradient reaches, and building it on a
pretrained encoder.pt. Tiny clouds (64 points) and batches keep it CPU-cheap."""

import numpy as np
import pytest
import torch

from corn_drake.contract import (ACTION_DIM, CONTEXT_DIM, CONTEXT_KEYS, STUDENT_OBS_KEYS,
                                 observation_size, student_observation_shapes)
from corn_drake.errors import InputError
from corn_drake.nn.encoders.corn_encoder import CORNEncoder
from corn_drake.nn.encoders.encoder_files import (NormalizedEncoder, make_policy_encoder,
                                                  save_encoder)
from corn_drake.nn.encoders.input_normalization import InputNormalization
from corn_drake.nn.student import PARAMETER_GROUPS, PRETRAINED_GROUPS, TOKEN_KEYS, StudentPolicy
from corn_drake.nn.student_io import student_from_encoder

POINTS = 64
ATOL = 1e-5


@pytest.fixture(scope="module")
def student():
    torch.manual_seed(0)
    return StudentPolicy().eval()


def _obs(batch: int, steps: int, seed: int = 0) -> dict[str, torch.Tensor]:
    rng = np.random.default_rng(seed)
    obs = {k: torch.from_numpy(rng.normal(size=(batch, steps, *shape))).float()
           for k, shape in student_observation_shapes(POINTS).items()}
    obs["cloud"] = obs["cloud"] * 0.05 + torch.tensor([0.0, 0.0, 0.45])  # an object on the table
    return obs


def _slice(obs, steps: slice, batch: slice = slice(None)):
    return {k: v[batch, steps] for k, v in obs.items()}


def test_output_shapes_and_token_layout(student):
    assert set(TOKEN_KEYS) | {"cloud", "hand_state"} == set(STUDENT_OBS_KEYS)
    out = student(_obs(3, 5))
    assert out.mean.shape == (3, 5, ACTION_DIM)
    assert out.log_std.shape == (ACTION_DIM,)
    assert out.hidden.shape == (2, 3, 128) == student.initial_state(3).shape
    assert not student.initial_state(3).any()
    # hand + one token per TOKEN_KEYS + 16 patches reach the transformer; 4 queries x 128 leave it
    obs = _obs(2, 1)
    flat = {k: v[:, 0] for k, v in obs.items()}
    extra = torch.zeros(2, len(TOKEN_KEYS), student.encoder.network.dim)
    tokens = student.encoder(flat["cloud"], flat["hand_state"], extra_tokens=extra)
    assert tokens.shape == (2, 1 + len(TOKEN_KEYS) + 16, 128)
    assert student.step_features(obs).shape == (2, 4 * 128)


def test_a_flattened_cloud_gives_the_same_actions(student):
    obs = _obs(2, 3)
    flat = dict(obs, cloud=obs["cloud"].flatten(2))
    assert torch.allclose(student(obs).mean, student(flat).mean, atol=ATOL)


@pytest.mark.parametrize("key", TOKEN_KEYS)
def test_every_task_token_reaches_the_action(student, key):
    # The extra tokens must be read: changing one input at step 2 changes the action from step 2
    # on (through the GRU) and leaves steps 0-1 as they were.
    obs = _obs(1, 4)
    changed = {k: v.clone() for k, v in obs.items()}
    changed[key][:, 2] += 1.0
    a, b = student(obs).mean, student(changed).mean
    assert torch.allclose(a[:, :2], b[:, :2], atol=ATOL)
    assert (a[:, 2:] - b[:, 2:]).abs().amax(-1).min() > 1e-4


def test_hidden_carried_across_calls_equals_one_call(student):
    obs = _obs(2, 8)
    whole = student(obs)
    first = student(_slice(obs, slice(0, 3)))
    second = student(_slice(obs, slice(3, 8)), first.hidden)
    assert torch.allclose(torch.cat([first.mean, second.mean], 1), whole.mean, atol=ATOL)
    assert torch.allclose(second.hidden, whole.hidden, atol=ATOL)
    # ...and the carried state matters: starting the second part afresh gives other actions.
    assert not torch.allclose(student(_slice(obs, slice(3, 8))).mean, second.mean, atol=1e-3)


def test_step_by_step_equals_the_sequence(student):
    # The LeafSystem's path (one step per call, hidden carried) against the training path.
    obs = _obs(2, 5)
    hidden, means = None, []
    for t in range(5):
        mean, hidden = student.step({k: v[:, t] for k, v in obs.items()}, hidden)
        means.append(mean)
    assert torch.allclose(torch.stack(means, 1), student(obs).mean, atol=ATOL)


def test_reset_at_a_marked_start_equals_a_fresh_run(student):
    obs = _obs(2, 8)
    carried_in = student(_obs(2, 4, seed=1)).hidden  # a state from an earlier episode
    starts = torch.zeros(2, 8, dtype=torch.bool)
    starts[0, 5] = True  # entry 0 begins a new episode at step 5; entry 1 runs on
    out = student(obs, carried_in, starts)
    fresh = student(_slice(obs, slice(5, 8), slice(0, 1)))
    assert torch.allclose(out.mean[0, 5:], fresh.mean[0], atol=ATOL)
    assert torch.allclose(out.hidden[:, 0], fresh.hidden[:, 0], atol=ATOL)
    unreset = student(obs, carried_in)
    assert torch.allclose(out.mean[1], unreset.mean[1], atol=ATOL)
    assert torch.allclose(out.mean[0, :5], unreset.mean[0, :5], atol=ATOL)
    assert not torch.allclose(out.mean[0, 5:], unreset.mean[0, 5:], atol=1e-3)
    # A start at step 0 discards the incoming state.
    at_zero = torch.zeros(2, 8, dtype=torch.bool)
    at_zero[:, 0] = True
    assert torch.allclose(student(obs, carried_in, at_zero).mean, student(obs).mean, atol=ATOL)


def _window_grads(student, hidden, starts=None):
    obs = _obs(1, 8, seed=2)
    goal = obs["goal"].requires_grad_(True)
    out = student(obs, hidden, starts)
    out.mean[0, -1].pow(2).sum().backward()
    return goal.grad[0]


def test_bptt_window_gradient_reaches_its_first_step_and_not_beyond():
    torch.manual_seed(0)
    student = StudentPolicy()
    previous = _obs(1, 8, seed=3)
    previous_goal = previous["goal"].requires_grad_(True)
    carried = student(previous).hidden

    grad = _window_grads(student, carried.detach())
    assert grad[0].abs().sum() > 0  # the last step's loss reaches the window's first input
    assert previous_goal.grad is None  # the detached state lets nothing into the last window
    # The detach is what stops it: without it the gradient flows into the previous window.
    _window_grads(student, carried)
    assert previous_goal.grad is not None and previous_goal.grad.abs().sum() > 0
    # An episode start inside the window cuts the gradient to the steps before it.
    starts = torch.zeros(1, 8, dtype=torch.bool)
    starts[0, 4] = True
    grad = _window_grads(student, carried.detach(), starts)
    assert not grad[:4].any() and grad[4:].abs().sum() > 0


def test_bad_inputs_are_named(student):
    obs = _obs(2, 3)
    with pytest.raises(KeyError, match="goal"):
        student({k: v for k, v in obs.items() if k != "goal"})
    with pytest.raises(ValueError, match="robot_state"):
        student(dict(obs, robot_state=obs["robot_state"][..., :-1]))
    with pytest.raises(ValueError, match="hidden"):
        student(obs, torch.zeros(2, 3, 128))
    with pytest.raises(ValueError, match="starts"):
        student(obs, None, torch.zeros(2, 4, dtype=torch.bool))
    with pytest.raises(ValueError, match="extra_tokens"):
        student.encoder(obs["cloud"][:, 0], obs["hand_state"][:, 0],
                        extra_tokens=torch.zeros(2, 3, 7))


def test_token_statistics_are_taken_from_the_teachers_context_keys():
    from corn_drake.rl.ppo.agent import obs_to_tensors

    # A teacher context assembled the teacher's way from known per-key values, used as the
    # statistics' mean: the student must pick out exactly its token keys' values.
    rng = np.random.default_rng(4)
    values = {k: rng.normal(size=(1, observation_size(k))) for k in CONTEXT_KEYS}
    context = obs_to_tensors(values)["context"][0].double()
    student = StudentPolicy()
    student.set_token_statistics_from_context(context, torch.full((CONTEXT_DIM,), 4.0))
    want = torch.from_numpy(np.concatenate([values[k][0] for k in TOKEN_KEYS])).float()
    assert torch.allclose(student.token_standardizer.mean, want)
    assert torch.allclose(student.token_standardizer.std, torch.full_like(want, 2.0))
    assert "token_standardizer.mean" in student.state_dict()
    with pytest.raises(ValueError, match="context statistics"):
        student.set_token_statistics_from_context(context[:-1], torch.ones(CONTEXT_DIM - 1))


def test_parameter_groups_cover_every_parameter_once(student):
    groups = student.parameter_groups()
    assert tuple(groups) == PARAMETER_GROUPS
    ids = [id(p) for ps in groups.values() for p in ps]
    assert len(ids) == len(set(ids)) == len(list(student.parameters()))


def _custom_encoder() -> NormalizedEncoder:
    torch.manual_seed(7)
    return NormalizedEncoder("corn", CORNEncoder(), InputNormalization((0.1, -0.2, 0.5), 0.3))


def test_built_from_a_pretrained_encoder_copies_its_weights(tmp_path):
    saved = _custom_encoder()
    save_encoder(tmp_path / "encoder.pt", saved, pretraining={"unseen_patch_f1": 0.9})
    torch.manual_seed(123)  # another seed: any fresh part would differ from the saved one
    student = student_from_encoder(tmp_path / "encoder.pt")
    net, ref = student.encoder.network, saved.network
    for name, tensor in ref.state_dict().items():
        assert torch.equal(net.state_dict()[name], tensor), name
    assert student.encoder.normalization.record() == {"center": pytest.approx([0.1, -0.2, 0.5]),
                                                      "scale": pytest.approx(0.3)}
    assert student.encoder.pretraining == {"unseen_patch_f1": 0.9}
    assert not torch.equal(StudentPolicy().encoder.network.hand.weight, net.hand.weight)
    # All of it is trained by default (the loader hands the encoder over frozen, in eval mode).
    summary = student.trainable_summary()
    assert all(g["trainable"] for g in summary.values()) and student.training
    assert student.encoder.training
    # Freezing named groups keeps exactly those out of training.
    frozen = student_from_encoder(tmp_path / "encoder.pt", frozen=("patch_tokenizer",))
    summary = frozen.trainable_summary()
    assert [g for g, s in summary.items() if not s["trainable"]] == ["patch_tokenizer"]
    assert summary["patch_tokenizer"]["parameters"] > 0
    assert set(PRETRAINED_GROUPS) < set(summary)


def test_wrong_checkpoints_and_groups_are_refused_naming_them(tmp_path):
    pointnet = tmp_path / "pn_encoder.pt"
    save_encoder(pointnet, make_policy_encoder("pointnet"))
    with pytest.raises(InputError, match=r"pn_encoder\.pt holds a pointnet"):
        student_from_encoder(pointnet)
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a checkpoint")
    with pytest.raises(InputError, match=r"garbage\.pt"):
        student_from_encoder(garbage)
    with pytest.raises(InputError, match=r"missing\.pt"):
        student_from_encoder(tmp_path / "missing.pt")
    good = tmp_path / "encoder.pt"
    save_encoder(good, _custom_encoder())
    with pytest.raises(InputError, match="tokeniser"):
        student_from_encoder(good, frozen=("tokeniser",))


def test_a_students_state_dict_restores_it_whole(tmp_path):
    # What a DAgger checkpoint relies on: a fresh StudentPolicy loading a trained one's
    # state_dict acts the same, the encoder's input normalisation and token statistics included.
    save_encoder(tmp_path / "encoder.pt", _custom_encoder())
    trained = student_from_encoder(tmp_path / "encoder.pt").eval()
    trained.set_token_statistics_from_context(torch.randn(CONTEXT_DIM), torch.rand(CONTEXT_DIM))
    restored = StudentPolicy().eval()
    restored.load_state_dict(trained.state_dict())
    assert restored.encoder.normalization.record() == trained.encoder.normalization.record()
    obs = _obs(1, 3)
    assert torch.equal(restored(obs).mean, trained(obs).mean)
