"""Contact pretraining: patch labels, augmentation consistency, a short run, resume, export."""

import json
import math

import numpy as np
import pytest
import torch

from corn_drake.config.pretraining import PretrainConfig
from corn_drake.pretraining.contact import Pretrainer, augment, hand9, patch_labels, prepare
from corn_drake.contact.runner import generate_dataset
from corn_drake.contract import ENCODER_INPUT_CENTER, ENCODER_INPUT_SCALE
from corn_drake.errors import InputError
from corn_drake.nn.encoders.encoder_files import (NormalizedEncoder, load_contact_model,
                                                  load_frozen_encoder, make_network, save_encoder)
from corn_drake.nn.geometry import quat_wxyz_to_matrix
from corn_drake.nn.encoders.input_normalization import InputNormalization
from corn_drake.nn.encoders.metrics import binary_metrics
from tests.fixtures import write_tiny_library


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("pre")
    lib = write_tiny_library(root / "lib")
    generate_dataset(lib, root / "data", num_samples=2048, seed=0, eval_samples=512,
                     shard_size=1024, progress=False)
    return root / "data"


def test_patch_label_is_any_point_in_patch():
    labels = torch.zeros(1, 8, dtype=torch.bool)
    labels[0, 5] = True
    knn = torch.tensor([[[0, 1], [5, 2], [3, 4]]])
    assert patch_labels(labels, knn).tolist() == [[False, True, False]]


def test_augmentation_moves_cloud_and_gripper_together():
    g = torch.Generator().manual_seed(0)
    cfg = PretrainConfig(point_noise_std=0.0)
    # Inputs from their own generator: drawn from torch's global one, they depended on which
    # tests ran before (a float32 distance then missed 1e-5 by 2e-7 in one order of the suite).
    inputs = torch.Generator().manual_seed(1)
    pts = torch.rand(4, 512, 3, generator=inputs)
    q = torch.nn.functional.normalize(torch.randn(4, 4, generator=inputs), dim=-1)
    pose = torch.cat([torch.rand(4, 3, generator=inputs), q], -1)
    norm = InputNormalization()
    new_pts, new_hand = augment(pts, pose, cfg, g, norm)
    # Distances from the gripper to every point are preserved (a rigid motion of both).
    before = torch.cdist(norm.points(pose[:, None, :3]), norm.points(pts))
    after = torch.cdist(new_hand[:, None, :3], new_pts)
    # float32 distances of up to ~2 m after a rotation and a shift: ~1e-5 of rounding is float32's
    torch.testing.assert_close(before, after, atol=5e-5, rtol=0)
    # The hand's rotation turned by the same yaw as the cloud.
    R0 = quat_wxyz_to_matrix(q)
    c0, c1 = new_hand[:, 3:6], new_hand[:, 6:9]
    assert torch.allclose(c0.norm(dim=-1), torch.ones(4), atol=1e-5)
    assert torch.allclose((c0 * c1).sum(-1), torch.zeros(4), atol=1e-5)
    assert torch.allclose(R0[..., 2, 0], c0[:, 2], atol=1e-5)  # yaw keeps the z components
    assert torch.allclose(hand9(pose, norm)[:, 3:].norm(dim=-1), torch.full((4,), math.sqrt(2)), atol=1e-5)


def test_metrics_against_hand_computed_values():
    m = binary_metrics(torch.tensor([2.0, -1.0, 0.5, -3.0]), torch.tensor([True, True, False, False]))
    assert m["accuracy"] == 0.5 and m["precision"] == 0.5 and m["recall"] == 0.5
    assert m["auroc"] == pytest.approx(0.75)


def test_short_run_learns_resumes_and_exports(data, tmp_path):
    cfg = PretrainConfig(model="corn", steps=60, batch_size=128, warmup_steps=5, eval_every=30,
                         checkpoint_every=30, eval_samples=512)
    first = Pretrainer(cfg, data, tmp_path)
    metrics = first.train(progress=False)
    assert metrics["parameters"] > 3e5
    for key in ("unseen_patch_accuracy", "unseen_patch_f1", "heldout_patch_auroc"):
        assert key in metrics
    # 60 steps only fit the base rate (beyond-chance patch learning starts after ~300 steps of
    # 256, see the budget run in docs/results/pretraining.md); the loss must still fall.
    assert first.history[-1]["loss"] < 0.6 < first.initial_loss
    assert (tmp_path / "plots" / "predictions.png").stat().st_size > 10_000
    encoder = load_frozen_encoder(tmp_path / "encoder.pt")
    assert not any(p.requires_grad for p in encoder.parameters())
    tokens = encoder(torch.randn(2, 512, 3), torch.randn(2, 9))
    assert tokens.shape == (2, 17, 128)
    # The export normalises world-frame inputs exactly as pretraining fed the network.
    assert encoder.normalization.record() == first.normalization.record()
    world = torch.rand(2, 512, 3) * 0.3 + 0.4
    pose = torch.cat([torch.rand(2, 3) * 0.3 + 0.4, torch.nn.functional.normalize(torch.randn(2, 4), dim=-1)], -1)
    pts, hand = prepare(world, pose, cfg, normalization=first.normalization)
    first.model.eval()
    with torch.no_grad():
        expected = first.model.encoder(pts, hand)
    hand_state = torch.cat([pose[:, :3], hand[:, 3:]], -1)  # world position + the same 6D
    torch.testing.assert_close(encoder(world, hand_state), expected, atol=1e-5, rtol=1e-5)
    # The file also holds the contact head: the whole contact model comes back from it alone.
    model, normalization = load_contact_model(tmp_path / "encoder.pt")
    assert normalization.record() == first.normalization.record() and not model.training
    with torch.no_grad():
        (logits, indices), (want, want_indices) = model(pts, hand), first.model(pts, hand)
    torch.testing.assert_close(logits, want, atol=1e-5, rtol=1e-5)
    assert logits.shape == (2, 16) and torch.equal(indices[1], want_indices[1])
    # Resume: a longer budget continues from step 60 with the saved optimizer state.
    cfg.steps = 70
    resumed = Pretrainer(cfg, data, tmp_path)
    assert resumed.step == 60
    assert resumed.optimizer.state_dict()["state"].keys() == first.optimizer.state_dict()["state"].keys()
    resumed.train(progress=False)
    assert json.loads((tmp_path / "metrics.json").read_text())["steps"] == 70


def test_an_encoder_file_without_a_contact_head_is_named(tmp_path):
    """Encoders exported before heads were kept, and pretext encoders, have no contact model."""
    torch.manual_seed(0)
    for kind, hint in (("corn", "re-export"), ("rot", "not contact-pretrained")):
        path = tmp_path / f"{kind}.pt"
        save_encoder(path, NormalizedEncoder(kind, make_network(kind), InputNormalization()))
        with pytest.raises(InputError, match=hint) as err:
            load_contact_model(path)
        assert str(path) in str(err.value)
    # A head of another shape (say a PointNet head saved with a corn encoder) is named too.
    path = tmp_path / "mixed.pt"
    save_encoder(path, NormalizedEncoder("corn", make_network("corn"), InputNormalization()),
                 contact_head=torch.nn.Linear(3, 1))
    with pytest.raises(InputError, match="contact head does not fit"):
        load_contact_model(path)
    # PointNet: point logits from the head kept beside the encoder.
    from corn_drake.nn.encoders.pointnet import PointNetContactModel

    trained = PointNetContactModel().eval()
    path = tmp_path / "pointnet.pt"
    save_encoder(path, NormalizedEncoder("pointnet", trained.encoder, InputNormalization()),
                 contact_head=trained.head)
    model, _ = load_contact_model(path)
    cloud, hand = _pose_batch(2)
    with torch.no_grad():
        torch.testing.assert_close(model(cloud, hand), trained(cloud, hand))


def _pose_batch(n):
    """World-frame clouds around the table and hand states (position + any 9-D rest)."""
    return torch.rand(n, 512, 3) * 0.4 + 0.3, torch.cat([torch.rand(n, 3) * 0.4 + 0.3, torch.randn(n, 6)], -1)


@pytest.mark.parametrize("kind", ["corn", "pointnet"])
def test_encoder_round_trip_keeps_its_normalisation(tmp_path, kind):
    """A saved encoder comes back with the normalisation it was saved with (here not the
    default), and gives the same output on the same world-frame input."""
    torch.manual_seed(0)
    norm = InputNormalization((0.1, -0.2, 0.5), 0.3)
    saved = NormalizedEncoder(kind, make_network(kind), norm).eval()
    save_encoder(tmp_path / "encoder.pt", saved, pretraining={"steps": 3})
    loaded = load_frozen_encoder(tmp_path / "encoder.pt")
    assert loaded.kind == kind and loaded.pretraining == {"steps": 3}
    assert loaded.normalization.record() == {"center": pytest.approx([0.1, -0.2, 0.5]),
                                             "scale": pytest.approx(0.3)}
    cloud, hand = _pose_batch(2)
    with torch.no_grad():
        torch.testing.assert_close(loaded(cloud, hand), saved(cloud, hand))
        # ...and not what the default normalisation would give: the record is used.
        default = NormalizedEncoder(kind, loaded.network, InputNormalization())
        assert not torch.allclose(default(cloud, hand), saved(cloud, hand), atol=1e-4)


def test_encoder_saved_before_the_normalisation_was_recorded_loads_with_the_one_used(tmp_path):
    old = tmp_path / "old.pt"
    torch.save({"kind": "corn", "state_dict": make_network("corn").state_dict(),
                "pretraining": None}, old)
    loaded = load_frozen_encoder(old)
    assert loaded.normalization.record() == {"center": pytest.approx(list(ENCODER_INPUT_CENTER)),
                                             "scale": pytest.approx(ENCODER_INPUT_SCALE)}


@pytest.mark.parametrize("record", [{"center": [0, 0], "scale": 0.4}, {"center": [0, 0, 0.5], "scale": 0.0},
                                    {"scale": 0.4}, "0.4"])
def test_a_malformed_normalisation_record_is_named(tmp_path, record):
    bad = tmp_path / "enc.pt"
    torch.save({"kind": "corn", "state_dict": make_network("corn").state_dict(),
                "normalization": record}, bad)
    with pytest.raises(InputError, match="enc.pt"):
        load_frozen_encoder(bad)


def test_bad_encoder_checkpoint_is_named(tmp_path):
    bad = tmp_path / "enc.pt"
    torch.save({"nothing": 1}, bad)
    with pytest.raises(ValueError, match="enc.pt"):
        load_frozen_encoder(bad)


def _pretrain_args(data, out, steps=60):
    return ["pretrain", "--data", str(data), "--out", str(out), "--model", "corn", "--steps",
            str(steps), "--batch-size", "8", "--eval-every", "10", "--no-progress"]


def test_pretraining_stopped_and_resumed_matches_an_uninterrupted_run_bitwise(data, tmp_path):
    """8 steps straight == 4 steps + resume to 8, bit for bit: the resume restores every RNG
    stream (dropout draws from torch's global one, which a new Pretrainer reseeds, as a new
    process would). The first 4 steps are all warm-up, whose learning rate does not depend on
    the step budget, so stopping the first run by its budget is a clean interruption."""
    def cfg(steps):
        return PretrainConfig(model="corn", steps=steps, batch_size=4, warmup_steps=4,
                              eval_every=100, checkpoint_every=100, eval_samples=16)

    Pretrainer(cfg(8), data, tmp_path / "straight").train(progress=False)
    Pretrainer(cfg(4), data, tmp_path / "resumed").train(progress=False)
    resumed = Pretrainer(cfg(8), data, tmp_path / "resumed")
    assert resumed.step == 4
    resumed.train(progress=False)
    a = torch.load(tmp_path / "straight" / "checkpoints" / "last.pt", weights_only=False)["model"]
    b = torch.load(tmp_path / "resumed" / "checkpoints" / "last.pt", weights_only=False)["model"]
    assert a.keys() == b.keys()
    for name in a:
        assert torch.equal(a[name], b[name]), f"{name} drifted after the resume"


def test_corrupt_pretraining_checkpoint_falls_back_to_the_previous_then_is_named(
        data, tmp_path, capsys):
    from corn_drake.cli import main
    from corn_drake.errors import InputError

    cfg = PretrainConfig(model="corn", steps=3, batch_size=8, warmup_steps=1, eval_every=2,
                         checkpoint_every=2, eval_samples=64)
    Pretrainer(cfg, data, tmp_path).train(progress=False)  # checkpoints at steps 2 and 3
    last = tmp_path / "checkpoints" / "last.pt"
    prev = last.with_name("prev.pt")
    with open(last, "r+b") as f:
        f.truncate(1000)
    capsys.readouterr()
    assert Pretrainer(cfg, data, tmp_path).step == 2
    err = capsys.readouterr().err
    assert "warning" in err and str(last) in err and str(prev) in err
    prev.write_bytes(b"garbage")
    with pytest.raises(InputError, match="prev.pt"):
        Pretrainer(cfg, data, tmp_path)
    # The command says it in one line (its run folder is OUT/corn).
    out = tmp_path / "cli"
    (out / "corn" / "checkpoints").mkdir(parents=True)
    for name in ("last.pt", "prev.pt"):
        (out / "corn" / "checkpoints" / name).write_bytes(b"garbage")
    assert main(_pretrain_args(data, out, steps=3)) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "last.pt" in err and "Traceback" not in err


def test_a_checkpoint_whose_network_changed_is_named_not_dumped(data, tmp_path):
    """A run folder of an older network (here: the PointNet's first layer cut back to the 12
    input channels it had before the gripper-frame input) is refused naming the checkpoint."""
    cfg = PretrainConfig(model="pointnet", steps=2, batch_size=4, warmup_steps=1, eval_every=100,
                         checkpoint_every=100, eval_samples=16)
    Pretrainer(cfg, data, tmp_path).train(progress=False)
    last = tmp_path / "checkpoints" / "last.pt"
    for path in (last, last.with_name("prev.pt")):
        if path.exists():
            state = torch.load(path, weights_only=False)
            state["model"]["encoder.layers.0.0.weight"] = state["model"]["encoder.layers.0.0.weight"][:, :12]
            torch.save(state, path)
    with pytest.raises(InputError, match=r"last\.pt holds pointnet weights this version's network"):
        Pretrainer(cfg, data, tmp_path)
