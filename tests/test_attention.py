"""The policy's attention over the object's patches: scores, the PolicySystem port, the Meshcat
view (live and in HTML recordings) and `evaluate --attention`.

Agents are randomly initialised with a fresh encoder. Such a head spreads its attention almost
uniformly (every patch near 1/16, changes of ~1e-4), so tests that need a measurable change
sharpen it: larger query and key weights make the softmax peaked, as a trained head's is.
"""

import numpy as np
import pytest
import torch
from pydrake.geometry import Meshcat

from corn_drake.errors import InputError
from corn_drake.evaluation.episodes import run_episode
from corn_drake.nn.attention import patch_scores
from corn_drake.nn.encoders.encoder_files import make_policy_encoder
from corn_drake.rl.ppo.agent import TeacherAgent
from corn_drake.rl.envs.teacher_env import TeacherEnv
from corn_drake.viz.attention_view import step_path, viridis_rgb
from tests.recordings import attention_in_recording

NUM_PATCHES = 16  # the encoder's patches (spec sheet: 16 FPS centres)


def _agent(kind: str = "corn", sharpen: float = 8.0) -> TeacherAgent:
    torch.manual_seed(0)
    agent = TeacherAgent(kind, make_policy_encoder("corn"))
    with torch.no_grad():
        agent.head.query.weight.mul_(sharpen)
        agent.head.key_value.weight.mul_(sharpen)
    return agent.eval()


@pytest.fixture(scope="module")
def observation():
    obs, _ = TeacherEnv().reset(seed=3)
    return obs


def _turned(obs: dict, angle: float, shift) -> dict:
    """`obs` with its cloud turned about its centroid's vertical axis and shifted."""
    c = obs["cloud"]
    m = c.mean(0)
    R = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    return dict(obs, cloud=((c - m) @ R.T + m + np.asarray(shift)).astype(np.float32))


def test_patch_scores_sum_the_queries_and_set_the_hand_token_apart():
    # Two queries over [hand, patch 0, patch 1]: each query's weights sum to 1.
    weights = torch.tensor([[[0.5, 0.25, 0.25], [0.0, 0.9, 0.1]]])
    scores, hand = patch_scores(weights)
    np.testing.assert_allclose(hand.numpy(), [0.25])  # mean weight on the hand token
    np.testing.assert_allclose(scores.numpy(), [[1.15 / 1.5, 0.35 / 1.5]], rtol=1e-6)
    with pytest.raises(ValueError, match="weights"):
        patch_scores(torch.ones(2, 3))


@pytest.mark.parametrize("kind", ["corn", "e2e"])
def test_scores_are_a_distribution_over_patches_that_follows_the_cloud(kind, observation):
    agent = _agent(kind)
    action, att = agent.act_and_attend(observation)
    np.testing.assert_array_equal(action, agent.act(observation))  # the same forward pass
    n = len(observation["cloud"])
    assert att.patch_scores.shape == (NUM_PATCHES,) and att.point_patch.shape == (n,)
    assert (att.patch_scores >= 0).all()
    assert att.patch_scores.sum() == pytest.approx(1.0, abs=1e-5)
    assert 0.0 <= att.hand_share <= 1.0
    assert att.patch_scores.max() > 2 / NUM_PATCHES  # peaked, not uniform
    # Every point is painted with one patch, and every patch has points.
    assert set(att.point_patch.tolist()) == set(range(NUM_PATCHES))
    np.testing.assert_array_equal(att.point_scores(), att.patch_scores[att.point_patch])

    # A rigid motion keeps the patches (FPS and kNN are invariant to it) but not the scores.
    moved = agent.attention(_turned(observation, 0.7, [0.05, 0.0, 0.0]))
    np.testing.assert_array_equal(moved.point_patch, att.point_patch)
    assert np.abs(moved.patch_scores - att.patch_scores).max() > 0.02
    assert moved.patch_scores.sum() == pytest.approx(1.0, abs=1e-5)
    # Each point's patch is its nearest centre: reshaping the cloud reassigns points.
    stretched = dict(observation, cloud=(observation["cloud"] * [1.6, 0.7, 1.0]).astype(np.float32))
    assert (agent.attention(stretched).point_patch != att.point_patch).any()

    # Batched: each row is the single observation's answer.
    batch = {k: np.stack([observation[k], _turned(observation, 0.7, [0.05, 0, 0])[k]])
             for k in observation}
    both = agent.attention(batch)
    np.testing.assert_allclose(both.patch_scores[0], att.patch_scores, atol=1e-6)
    np.testing.assert_allclose(both.patch_scores[1], moved.patch_scores, atol=1e-6)


def test_an_untouched_random_head_still_reacts_to_the_cloud(observation):
    agent = _agent(sharpen=1.0)
    before = agent.attention(observation).patch_scores
    after = agent.attention(_turned(observation, 0.7, [0.05, 0.0, 0.0])).patch_scores
    assert np.abs(after - before).max() > 1e-5 and after.sum() == pytest.approx(1.0, abs=1e-5)


def test_policies_without_cross_attention_refuse(observation):
    from corn_drake.systems.policies.policy import PolicySystem

    pn = TeacherAgent("pn", make_policy_encoder("pointnet"))
    for agent in (TeacherAgent("state"), pn):
        assert not agent.has_attention
        with pytest.raises(InputError, match=f"{agent.kind!r} has no cross-attention"):
            agent.act_and_attend(observation)
        with pytest.raises(ValueError, match="no cross-attention"):
            PolicySystem(agent, attention=True)
    with pytest.raises(ValueError, match="meshcat"):
        TeacherEnv(agent=_agent(), attention=True)  # nowhere to draw it


def test_policy_system_attention_port_is_the_agents_own_and_shares_its_forward_pass():
    agent = _agent()
    calls = []
    act_and_attend = agent.act_and_attend
    agent.act_and_attend = lambda *a: calls.append(1) or act_and_attend(*a)
    meshcat = Meshcat()
    env = TeacherEnv(agent=agent, meshcat=meshcat, attention=True)
    policy = env.handles.policy
    assert policy.HasOutputPort("attention") and policy.HasOutputPort("point_attention")
    env.reset(seed=5)
    seen = []
    for step in range(4):
        ctx = policy.GetMyContextFromRoot(env.context)
        obs = policy.observation(ctx)
        own_action, own = act_and_attend(obs)
        ports = {name: policy.GetOutputPort(name).Eval(ctx)
                 for name in ("attention", "point_attention", "action")}
        np.testing.assert_allclose(ports["attention"], own.patch_scores, atol=1e-7)
        np.testing.assert_allclose(ports["point_attention"], own.point_scores(), atol=1e-7)
        np.testing.assert_allclose(ports["action"], own_action, atol=1e-7)
        seen.append(ports["attention"])
        # The view drew this step (the inputs of the action latched now).
        assert meshcat.HasPath(step_path("/attention", step))
        env.step()
    # One network pass per policy step: the view, the latch and the ports above share it.
    assert len(calls) == 1 + 4  # the reset's observation, then one per step
    assert np.abs(np.diff(seen, axis=0)).max() > 1e-3  # the attention follows the episode
    # A policy system without attention keeps its one output.
    plain = TeacherEnv(agent=agent).handles.policy
    assert not plain.HasOutputPort("attention")
    # Sampled actions: the shared pass takes the RandomSource's draw like act() does.
    with torch.no_grad():
        agent.log_std.fill_(-1.0)
    sampled = TeacherEnv(agent=agent, meshcat=meshcat, stochastic_policy=True, attention=True)
    sampled.reset(seed=5)
    policy = sampled.handles.policy
    ctx = policy.GetMyContextFromRoot(sampled.context)
    obs, noise = policy.observation(ctx), policy.GetInputPort("unit_noise").Eval(ctx)
    np.testing.assert_allclose(policy.GetOutputPort("action").Eval(ctx), agent.act(obs, noise),
                               atol=1e-7)
    assert np.abs(agent.act(obs, noise) - agent.act(obs)).max() > 1e-3
    np.testing.assert_allclose(policy.GetOutputPort("attention").Eval(ctx),
                               act_and_attend(obs)[1].patch_scores, atol=1e-7)


def test_recordings_show_each_steps_colours_at_its_step(tmp_path):
    agent = _agent()
    env = TeacherEnv(agent=agent, meshcat=Meshcat(), attention=True)
    policy, view = env.handles.policy, env.diagram.GetSubsystemByName("attention_view")
    first = run_episode(env, seed=1, max_steps=4, record_path=tmp_path / "a.html")
    assert first.steps == 4
    objects, tracks = attention_in_recording(first.recording.read_text())
    paths = [step_path(view.path, k) for k in range(5)]  # the start and after each step
    assert sorted(objects) == paths
    fps = 64  # run_episode's StartRecording default
    frames = [int(env.clock.boundary(k) * fps) for k in range(5)]
    for k, path in enumerate(paths):
        assert objects[path]["object"]["object"]["type"] == "Points"
        keys = dict(tracks[path])
        assert keys[frames[k]] is True  # shown at its step...
        if k > 0:
            assert keys[0] is False  # ...hidden before it...
        if k < 4:
            assert keys[frames[k + 1]] is False  # ...and after it
    # The last step's colours are viridis of the scores the port gives at the episode's end.
    scores = policy.GetOutputPort("point_attention").Eval(policy.GetMyContextFromRoot(env.context))
    color = objects[paths[-1]]["object"]["geometries"][0]["data"]["attributes"]["color"]
    # Meshcat packs typed arrays as msgpack extension types (code 23: Float32Array).
    assert color["array"].code == 23
    drawn = np.frombuffer(color["array"].data, np.float32).reshape(-1, 3)
    np.testing.assert_allclose(drawn, viridis_rgb(scores) / 255.0, atol=1e-6)
    assert len(np.unique(drawn, axis=0)) > 1  # coloured by patch, not one colour

    # A shorter episode after it: nothing of the first one's later steps is left.
    second = run_episode(env, seed=2, max_steps=2, record_path=tmp_path / "b.html")
    objects, tracks = attention_in_recording(second.recording.read_text())
    assert sorted(objects) == sorted(tracks) == paths[:3]


def test_viridis_colours_are_relative_to_the_steps_top_score():
    rgb = viridis_rgb(np.array([0.0, 0.05, 0.1]))
    assert rgb.dtype == np.uint8 and rgb.shape == (3, 3)
    np.testing.assert_array_equal(rgb, viridis_rgb(np.array([0.0, 0.5, 1.0])))
    assert rgb[2, 1] > 200 and rgb[0, 2] > rgb[0, 1]  # top: yellow; zero: dark purple
    with pytest.raises(ValueError, match="scores"):
        viridis_rgb(np.array([0.1, -0.2]))


def _write_run(run, policy: str) -> None:
    """A run folder holding a fresh agent of `policy` (e2e/state need no encoder file)."""
    from corn_drake.config.training import TrainConfig
    from corn_drake.storage.checkpoint_files import save_checkpoint
    from corn_drake.run_folders.config_file import write_run_config

    cfg = TrainConfig(policy=policy)
    cfg.env.task.episode_steps = 3
    write_run_config(cfg, run)
    agent = _agent("e2e") if policy == "e2e" else TeacherAgent(policy)
    save_checkpoint(run / "checkpoints" / "last.pt", {"agent": agent.state_dict()})


def test_evaluate_attention_paints_an_e2e_run_and_refuses_others(tmp_path, capsys):
    from corn_drake.cli import main

    _write_run(tmp_path / "e2e", "e2e")
    report = tmp_path / "e2e.json"
    assert main(["evaluate", "--run", str(tmp_path / "e2e"), "--attention", "--episodes", "1",
                 "--record", "1", "--report", str(report)]) == 0
    (html,) = (tmp_path / "e2e_recordings").glob("*.html")
    objects, tracks = attention_in_recording(html.read_text())
    assert len(objects) == 4 and sorted(objects) == sorted(tracks)

    _write_run(tmp_path / "state", "state")
    for run, named in ((str(tmp_path / "state"), "'state' policy"), ("scripted", "reference")):
        capsys.readouterr()
        out = tmp_path / "refused.json"
        assert main(["evaluate", "--run", run, "--attention", "--episodes", "1",
                     "--report", str(out)]) == 2
        err = capsys.readouterr().err
        assert "--attention" in err and named in err
        assert not out.exists() and not (tmp_path / "refused_recordings").exists()
