"""The `p2v-lite` and `rot` policies: a frozen pretext-pretrained patch encoder under the same
cross-attention head as `corn`. Each builds from its own encoder.pt, acts, trains (features
cached, the encoder untouched), loads back from its run checkpoint, and refuses an encoder of
another kind or one that did not learn its pretext task.

The environments are replaced by random observations of the contract's shapes
(tests/test_feature_cache.RandomEnvs): what is checked is the policy, not the simulation.
"""

import numpy as np
import pytest
import torch

from corn_drake.cli import main
from corn_drake.config.training import TrainConfig
from corn_drake.contract import ACTION_DIM, observation_shapes
from corn_drake.errors import InputError
from corn_drake.config.pretraining import pretext_config
from corn_drake.nn.encoders.encoder_files import make_policy_encoder, save_encoder
from corn_drake.nn.policy import CrossAttentionActorCritic
from corn_drake.pretraining.pretext import PretextPretrainer
from corn_drake.rl.ppo.agent import TeacherAgent
from corn_drake.rl.ppo.teacher_runs import load_run
from corn_drake.rl.pretrained_encoders import MIN_PRETEXT_SKILL, load_encoder
from corn_drake.rl.ppo.segments import SegmentCollector
from corn_drake.rl.training.ppo_trainer import Trainer
from corn_drake.run_folders.config_file import write_run_config
from tests.fixtures import write_tiny_library
from tests.test_feature_cache import NUM_POINTS, RandomEnvs

PRETEXT_POLICIES = ["p2v-lite", "rot"]


@pytest.fixture(scope="module")
def pretrained(tmp_path_factory):
    """{kind: encoder.pt} from one-step pretext runs (their skill is below the bar, so the
    policies take them with allow_weak_encoder), plus a contact-kind `corn` export."""
    root = tmp_path_factory.mktemp("encoders")
    library = write_tiny_library(root / "lib")
    paths = {}
    for kind in PRETEXT_POLICIES:
        cfg = pretext_config(kind, steps=1, batch_size=2, eval_samples=4)
        PretextPretrainer(cfg, library, root / kind).train(progress=False)
        paths[kind] = root / kind / "encoder.pt"
    paths["corn"] = root / "corn.pt"
    save_encoder(paths["corn"], make_policy_encoder("corn"), pretraining={"unseen_patch_f1": 0.95})
    return paths


def _observation(seed=0):
    rng = np.random.default_rng(seed)
    return {k: rng.normal(size=shape).astype(np.float32)
            for k, shape in observation_shapes(NUM_POINTS).items()}


@pytest.mark.parametrize("kind", PRETEXT_POLICIES)
def test_the_policy_builds_acts_trains_and_loads_from_its_run_checkpoint(
        kind, pretrained, tmp_path, monkeypatch):
    encoder = load_encoder(kind, pretrained[kind], allow_weak=True)
    assert encoder.kind == kind
    agent = TeacherAgent(kind, encoder)
    assert isinstance(agent.head, CrossAttentionActorCritic) and agent.frozen_encoder
    action = agent.act(_observation())
    assert action.shape == (ACTION_DIM,) and np.all(np.abs(action) <= 1)

    monkeypatch.setattr(Trainer, "_make_rollouts",
                        lambda self, n: SegmentCollector(RandomEnvs(n), self.agent, self.device))
    cfg = TrainConfig(policy=kind, encoder=str(pretrained[kind]), allow_weak_encoder=True,
                      total_steps=16, envs_per_worker=2, rollout_steps=8, checkpoint_every=100)
    before = {k: v.clone() for k, v in encoder.state_dict().items()}
    trainer = Trainer(cfg, tmp_path, encoder)
    trainer.train(progress=False)
    assert trainer.global_step == 16
    # Frozen: PPO never changed the pretrained encoder.
    for name, value in trainer.agent.encoder.state_dict().items():
        assert torch.equal(value, before[name]), name
    write_run_config(cfg, tmp_path)  # what `corn-drake train` writes beside the checkpoint
    loaded_cfg, loaded = load_run(tmp_path)
    assert loaded_cfg.policy == kind and loaded.kind == kind and loaded.encoder.kind == kind
    obs = _observation(1)
    np.testing.assert_array_equal(loaded.act(obs), trainer.agent.eval().act(obs))
    # ...and the trained head, not a fresh one, acts.
    assert not np.array_equal(loaded.act(obs), TeacherAgent(kind, encoder).act(obs))


@pytest.mark.parametrize("policy, holds", [("p2v-lite", "corn"), ("corn", "p2v-lite"),
                                           ("rot", "p2v-lite"), ("p2v-lite", "rot")])
def test_an_encoder_of_another_kind_is_refused_naming_both(pretrained, policy, holds):
    path = pretrained[holds]
    with pytest.raises(InputError) as refused:
        load_encoder(policy, path, allow_weak=True)
    message = str(refused.value)
    assert f"needs a {policy} encoder" in message and f"holds a {holds} one" in message
    assert str(path) in message


def test_train_refuses_a_wrong_kind_before_writing(pretrained, tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["train", "--policy", "p2v-lite", "--encoder", str(pretrained["corn"]),
                 "--steps", "16", "--envs-per-worker", "2", "--rollout-steps", "8",
                 "--no-progress", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert "p2v-lite" in err[0] and "holds a corn one" in err[0] and str(pretrained["corn"]) in err[0]
    assert not (out / "config.yaml").exists()


def test_a_pretext_encoder_is_held_to_its_skill_bar(tmp_path, capsys):
    def export(name, kind, **record):
        path = tmp_path / name
        save_encoder(path, make_policy_encoder(kind), pretraining=record or None)
        return path

    weak = export("weak.pt", "rot", unseen_pretext_skill=0.05, heldout_pretext_skill=0.9)
    with pytest.raises(InputError, match=r"weak\.pt reached rot pretext skill 0\.050"):
        load_encoder("rot", weak)
    assert load_encoder("rot", weak, allow_weak=True).kind == "rot"
    assert "0.050" in capsys.readouterr().err
    good = export("good.pt", "p2v-lite", heldout_pretext_skill=MIN_PRETEXT_SKILL + 0.01)
    assert load_encoder("p2v-lite", good).pretraining["heldout_pretext_skill"] > MIN_PRETEXT_SKILL
    # A contact F1 says nothing about a pretext encoder.
    with pytest.raises(InputError, match="records no pretraining metrics"):
        load_encoder("p2v-lite", export("f1.pt", "p2v-lite", unseen_patch_f1=0.99))
