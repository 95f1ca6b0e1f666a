"""A frozen encoder that never learned contact is not silently used by a policy (issue: the `pn`
baseline once froze a PointNet with patch F1 0.000), and the two PointNet budgets stay apart."""

import json

import pytest
import torch

from corn_drake.cli import main as cli
from corn_drake.errors import InputError
from corn_drake.nn.encoders.encoder_files import (load_frozen_encoder, make_network,
                                                  make_policy_encoder, save_encoder)
from corn_drake.rl.pretrained_encoders import MIN_CONTACT_F1, contact_f1, load_encoder


def _export(path, kind, **metrics):
    save_encoder(path, make_policy_encoder(kind), pretraining=metrics or None)
    return path


def test_pretraining_record_travels_with_the_encoder(tmp_path):
    path = _export(tmp_path / "e.pt", "pointnet", steps=367, unseen_patch_f1=0.0)
    assert load_frozen_encoder(path).pretraining == {"steps": 367, "unseen_patch_f1": 0.0}


@pytest.mark.parametrize("policy, kind", [("pn", "pointnet"), ("corn", "corn")])
def test_an_encoder_below_the_bar_is_refused_naming_it(tmp_path, policy, kind):
    weak = _export(tmp_path / "weak.pt", kind, unseen_patch_f1=0.0, heldout_patch_f1=0.1)
    with pytest.raises(InputError, match=r"weak\.pt.*F1 0\.000"):
        load_encoder(policy, weak)
    unrecorded = tmp_path / "old.pt"  # an export from before the record existed
    torch.save({"kind": kind, "state_dict": make_network(kind).state_dict()}, unrecorded)
    with pytest.raises(InputError, match="records no pretraining metrics"):
        load_encoder(policy, unrecorded)


def test_a_learned_encoder_is_accepted_and_weak_ones_only_with_the_flag(tmp_path, capsys):
    good = _export(tmp_path / "good.pt", "pointnet", unseen_patch_f1=MIN_CONTACT_F1 + 0.01)
    loaded = load_encoder("pn", good)
    assert loaded.kind == "pointnet" and loaded.pretraining["unseen_patch_f1"] > MIN_CONTACT_F1
    weak = _export(tmp_path / "weak.pt", "pointnet", unseen_patch_f1=0.2)
    assert load_encoder("pn", weak, allow_weak=True) is not None
    assert "0.200" in capsys.readouterr().err  # the override is never silent


def test_an_encoder_of_the_wrong_kind_is_refused(tmp_path):
    pointnet = _export(tmp_path / "pn.pt", "pointnet", unseen_patch_f1=0.95)
    with pytest.raises(InputError, match=r"needs a corn encoder.*pn\.pt holds a pointnet"):
        load_encoder("corn", pointnet)


def test_unseen_f1_is_preferred_and_nan_falls_back_to_held_out():
    assert contact_f1({"unseen_patch_f1": 0.9, "heldout_patch_f1": 0.1}) == 0.9
    assert contact_f1({"unseen_patch_f1": float("nan"), "heldout_patch_f1": 0.85}) == 0.85
    assert contact_f1(None) is None


def test_train_cli_refuses_a_weak_encoder_before_writing(tmp_path, capsys):
    weak = _export(tmp_path / "weak.pt", "pointnet", unseen_patch_f1=0.0)
    out = tmp_path / "run"
    code = cli(["train", "--policy", "pn", "--encoder", str(weak), "--steps", "64",
                "--envs-per-worker", "2", "--rollout-steps", "8", "--no-progress", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--allow-weak-encoder" in err[0]
    assert not (out / "config.yaml").exists()


def test_equal_time_pointnet_is_its_own_row(tmp_path):
    """--pointnet-budget time writes OUT/pointnet_equal_time, never OUT/pointnet (the paper's
    equal-steps row), and metrics.json keeps each under its own key."""
    from tests.fixtures import write_tiny_library
    from corn_drake.contact.runner import generate_dataset

    lib = write_tiny_library(tmp_path / "lib")
    generate_dataset(lib, tmp_path / "data", num_samples=256, seed=0, eval_samples=128,
                     shard_size=256, progress=False)
    out = tmp_path / "pre"
    assert cli(["pretrain", "--data", str(tmp_path / "data"), "--out", str(out), "--model", "both",
                "--steps", "2", "--batch-size", "8", "--eval-every", "2", "--pointnet-budget",
                "time", "--no-progress"]) == 0
    assert (out / "pointnet_equal_time" / "encoder.pt").is_file()
    assert not (out / "pointnet").exists()
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["pointnet_equal_time"]["budget"]["kind"] == "equal_wall_clock"
    assert "pointnet" not in metrics and metrics["model"] == "corn"


def test_a_pointnet_from_before_the_gripper_frame_input_is_refused_by_name(tmp_path):
    """Old 12-channel PointNet files fail naming the file and the mismatch, not with a dump."""
    path = tmp_path / "old_pn.pt"
    save_encoder(path, make_policy_encoder("pointnet"))
    state = torch.load(path, weights_only=False)
    state["state_dict"]["layers.0.0.weight"] = state["state_dict"]["layers.0.0.weight"][:, :12]
    torch.save(state, path)
    with pytest.raises(InputError, match=r"old_pn\.pt holds pointnet weights this version's network "
                                         r"does not fit \(size mismatch for layers\.0\.0\.weight") as e:
        load_frozen_encoder(path)
    assert "\n" not in str(e.value)


def test_a_weak_encoder_is_warned_about_once_per_content(tmp_path, capsys, monkeypatch):
    """`make demo` loads its weak encoder three times (two of them the run folder's copy): one
    warning, not three; another weak encoder still gets its own."""
    import shutil

    from corn_drake.rl import pretrained_encoders

    monkeypatch.setattr(pretrained_encoders, "_warned", set())
    weak = _export(tmp_path / "weak.pt", "corn", unseen_patch_f1=0.0)
    copy = tmp_path / "run" / "encoder.pt"
    copy.parent.mkdir()
    shutil.copyfile(weak, copy)
    for path in (weak, copy, weak):
        load_encoder("corn", path, allow_weak=True)
    assert capsys.readouterr().err.count("warning:") == 1
    other = _export(tmp_path / "other.pt", "corn", unseen_patch_f1=0.1)
    load_encoder("corn", other, allow_weak=True)
    err = capsys.readouterr().err
    assert err.count("warning:") == 1 and "other.pt" in err
