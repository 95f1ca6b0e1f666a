"""Pretext pretraining (P2V-lite, ROT): the losses learn, the loop resumes, the export loads with
its kind, the command checks its arguments."""

import json
import math

import pytest
import torch

from corn_drake.cli import main
from corn_drake.config.pretraining import PretextConfig, pretext_config
from corn_drake.errors import InputError
from corn_drake.nn.encoders.encoder_files import load_frozen_encoder
from corn_drake.nn.geometry import matrix_from_rot6d, random_rotations, rot6d, rotation_angle
from corn_drake.pretext.p2v import SHARED, ema_decay, random_patch_mask
from corn_drake.pretraining.pretext import PretextPretrainer
from corn_drake.pretext.rot import chordal_mean
from tests.fixtures import write_tiny_library


@pytest.fixture(scope="module")
def library(tmp_path_factory):
    return write_tiny_library(tmp_path_factory.mktemp("pretext") / "lib")


def _cfg(model, steps, **fields):
    values = {"batch_size": 4, "eval_samples": 8, "eval_every": 100, "checkpoint_every": 100,
              **fields}
    return pretext_config(model, steps=steps, **values)


def _fit_tiny_set(trainer, steps):
    """`steps` optimiser steps (the trainer's own: schedule, clipping, EMA teacher) on the fixed
    8 samples of its "train" evaluation set; (metrics before, metrics after) on that set."""
    tiny = trainer.eval_set("train")
    before = trainer.evaluate("train")
    for _ in range(steps):
        trainer.optimize(trainer.loss_on(tiny))
    return before, trainer.evaluate("train")


def test_p2v_lite_loss_goes_down_on_a_tiny_dataset(library, tmp_path):
    # A 1000-step budget: the learning rate stays near its peak and the teacher's EMA time
    # constant is ~76 steps over the 40 taken.
    trainer = PretextPretrainer(_cfg("p2v-lite", 1000, dropout=0.0, warmup_steps=2), library,
                                tmp_path)
    before, after = _fit_tiny_set(trainer, 40)
    assert after["loss"] < 0.75 * before["loss"]
    # Below the best input-blind prediction (the mean target), so the student reads its
    # input; and not by a collapse of the teacher (targets with ~0 spread over patches).
    assert after["skill"] > 0.15 > before["skill"]
    assert after["target_std"] > 0.5


def test_rot_loss_goes_down_on_a_tiny_dataset(library, tmp_path):
    trainer = PretextPretrainer(_cfg("rot", 30, dropout=0.0, warmup_steps=2, lr=1e-3),
                                library, tmp_path)
    before, after = _fit_tiny_set(trainer, 30)
    assert after["loss"] < 0.5 * before["loss"]
    # Well below the best constant rotation for these 8 pairs: the prediction depends on the
    # clouds (measured: skill ~0.9 after 20 steps).
    assert after["skill"] > 0.5 > 0 > before["skill"]
    assert after["rotation_error_deg"] < before["rotation_error_deg"]


def test_p2v_lite_killed_and_resumed_matches_an_uninterrupted_run_bitwise(library, tmp_path):
    """4 steps straight == 4 steps killed after the step-2 checkpoint and resumed, bit for bit:
    the checkpoint holds the EMA teacher and every RNG stream. (The budget stays 4: the EMA
    schedule, like the learning rate's, is a function of the run's length.)"""
    class Killed(Exception):
        pass

    cfg = _cfg("p2v-lite", 4, checkpoint_every=2, eval_samples=4)
    PretextPretrainer(cfg, library, tmp_path / "straight").train(progress=False)
    first = PretextPretrainer(cfg, library, tmp_path / "resumed")
    draw_batch = first.batch_loss

    def killed_after_step_2():
        if first.step == 2:
            raise Killed
        return draw_batch()

    first.batch_loss = killed_after_step_2
    with pytest.raises(Killed):
        first.train(progress=False)
    resumed = PretextPretrainer(cfg, library, tmp_path / "resumed")
    assert resumed.step == 2
    resumed.train(progress=False)
    a = torch.load(tmp_path / "straight" / "checkpoints" / "last.pt", weights_only=False)["model"]
    b = torch.load(tmp_path / "resumed" / "checkpoints" / "last.pt", weights_only=False)["model"]
    assert any(name.startswith("teacher.") for name in a)
    for name in a:
        assert torch.equal(a[name], b[name]), f"{name} drifted after the resume"


@pytest.mark.parametrize("model", ["p2v-lite", "rot"])
def test_a_run_exports_an_encoder_of_its_kind_with_its_record(library, tmp_path, model):
    trainer = PretextPretrainer(_cfg(model, 2, eval_every=1), library, tmp_path)
    metrics = trainer.train(progress=False)
    # Step-0 row: the untrained model on the held-out split, then one per evaluation.
    assert [row["step"] for row in trainer.history] == [0, 1, 2]
    for key in ("heldout_pretext_loss", "heldout_pretext_skill", "unseen_pretext_loss",
                "unseen_pretext_skill", "untrained_heldout_pretext_loss"):
        assert math.isfinite(metrics[key]), key
    assert metrics["pretext"] == model and metrics["train_objects"] == 3
    assert json.loads((tmp_path / "metrics.json").read_text())["steps"] == 2
    encoder = load_frozen_encoder(tmp_path / "encoder.pt")
    assert encoder.kind == model
    assert encoder.pretraining["unseen_pretext_skill"] == metrics["unseen_pretext_skill"]
    assert encoder(torch.rand(2, 512, 3), torch.rand(2, 9)).shape == (2, 17, 128)
    # The export is the trained network (the student for P2V-lite), not a fresh one.
    for name, p in encoder.network.state_dict().items():
        assert torch.equal(p, trainer.model.encoder.state_dict()[name])


def test_a_resumed_run_of_the_other_model_is_refused(library, tmp_path):
    PretextPretrainer(_cfg("rot", 1), library, tmp_path).train(progress=False)
    with pytest.raises(InputError, match="holds a 'rot' model"):
        PretextPretrainer(_cfg("p2v-lite", 2), library, tmp_path)


def test_ema_schedule_keeps_point2vec_time_constants_as_fractions_of_the_run():
    c = PretextConfig()
    args = (c.ema_start_horizon, c.ema_end_horizon, c.ema_ramp_fraction)
    # At point2vec's own length (800 epochs of 82 steps) the decays are its 0.9998 -> 0.99999.
    total = 65_600
    assert ema_decay(0, total, *args) == pytest.approx(0.9998, abs=2e-6)
    assert ema_decay(total // 4, total, *args) == pytest.approx(0.99999, abs=1e-7)
    assert ema_decay(total // 8, total, *args) == pytest.approx((0.9998 + 0.99999) / 2, abs=2e-6)
    assert ema_decay(total - 1, total, *args) == ema_decay(total // 4, total, *args)
    # A 2000-step run's teacher starts with a ~150-step time constant, not point2vec's 5000.
    assert 1 / (1 - ema_decay(0, 2000, *args)) == pytest.approx(152, abs=1)


def test_the_teacher_averages_the_layers_and_copies_the_shared_embeddings(library, tmp_path):
    model = PretextPretrainer(_cfg("p2v-lite", 1), library, tmp_path).model
    with torch.no_grad():
        for p in model.encoder.parameters():
            p.add_(1.0)
    before = {k: v.clone() for k, v in model.teacher.state_dict().items()}
    model.update_teacher(0.75)
    student = model.encoder.state_dict()
    for name, value in model.teacher.state_dict().items():
        if name.split(".")[0] in SHARED:
            assert torch.equal(value, student[name]), name
        else:
            torch.testing.assert_close(value, 0.75 * before[name] + 0.25 * student[name])
    assert not model.teacher.training  # targets never see dropout
    model.train()
    assert not model.teacher.training


def test_patch_mask_masks_the_ratio_of_every_cloud():
    mask = random_patch_mask(5, 16, 0.65, torch.Generator().manual_seed(0))
    assert mask.sum(1).tolist() == [10] * 5
    assert len({tuple(row.tolist()) for row in mask}) > 1


def test_rotation_helpers():
    R = random_rotations(6, torch.Generator().manual_seed(0))
    torch.testing.assert_close(matrix_from_rot6d(rot6d(R)), R, atol=1e-5, rtol=0)
    # A 6D vector that is not orthonormal still gives a rotation.
    M = matrix_from_rot6d(torch.randn(4, 6))
    torch.testing.assert_close(M @ M.transpose(1, 2), torch.eye(3).expand(4, 3, 3), atol=1e-5, rtol=0)
    assert torch.allclose(torch.det(M), torch.ones(4), atol=1e-5)
    quarter = torch.tensor([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    assert rotation_angle(quarter, torch.eye(3)).item() == pytest.approx(math.pi / 2, abs=1e-5)
    # The chordal mean of copies of one rotation is that rotation.
    torch.testing.assert_close(chordal_mean(R[:1].expand(5, 3, 3)), R[0], atol=1e-5, rtol=0)


def _pretrain(*args):
    return main(["pretrain", *args, "--steps", "1", "--batch-size", "2", "--eval-every", "1",
                 "--eval-samples", "4", "--no-progress"])


def test_the_command_writes_the_model_folder_and_checks_its_data_argument(library, tmp_path, capsys):
    out = tmp_path / "out"
    assert _pretrain("--model", "rot", "--objects", str(library), "--out", str(out)) == 0
    assert load_frozen_encoder(out / "rot" / "encoder.pt").kind == "rot"
    assert "unseen pretext skill" in capsys.readouterr().out
    for args, says in ((["--model", "rot"], "needs --objects"),
                       (["--model", "p2v-lite", "--objects", str(library), "--data", "x"], "--data is contact data"),
                       (["--model", "corn", "--objects", str(library)], "--objects is the data of"),
                       (["--model", "p2v-lite", "--objects", str(tmp_path / "none")], "none")):
        assert _pretrain(*args, "--out", str(tmp_path / "bad")) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and says in err, err
    assert not (tmp_path / "bad").exists()  # refused before anything was written
    # A resume with another library is refused before anything is written.
    other = write_tiny_library(tmp_path / "other")
    assert _pretrain("--model", "rot", "--objects", str(other), "--out", str(out)) == 2
    assert "--objects" in capsys.readouterr().err
