"""DAgger distillation (rl/training/dagger.py, `corn-drake distill`): the KL loss, learning on a fixed
dataset, what a BPTT window's gradient reaches, a killed run's resume, and bad input.

The slow tests train a tiny `state` teacher (it only labels states, so it needs no encoder) and
distil it into a student on a random, unpretrained CORN encoder (--allow-weak-encoder) with
ground-truth segmentation, 2 envs and 10-step episodes."""

import json

import numpy as np
import pytest
import torch

from corn_drake.cli import main as cli
from corn_drake.config.training import DistillConfig
from corn_drake.contract import ACTION_DIM, student_observation_shapes
from corn_drake.storage.checkpoint_files import load_checkpoint
from corn_drake.nn.encoders.encoder_files import make_policy_encoder, save_encoder
from corn_drake.nn.student import StudentPolicy
from corn_drake.rl.training.dagger import gaussian_kl, window_loss, window_terms

POINTS = 64


def _obs(batch: int, steps: int, seed: int = 0) -> dict[str, torch.Tensor]:
    rng = np.random.default_rng(seed)
    obs = {k: torch.from_numpy(rng.normal(size=(batch, steps, *shape))).float()
           for k, shape in student_observation_shapes(POINTS).items()}
    obs["cloud"] = obs["cloud"] * 0.05 + torch.tensor([0.0, 0.0, 0.45])
    return obs


def test_kl_is_zero_for_identical_gaussians_and_matches_torch_otherwise():
    g = torch.Generator().manual_seed(0)
    mean = torch.randn(5, ACTION_DIM, generator=g)
    log_std = torch.randn(ACTION_DIM, generator=g) * 0.3
    assert torch.allclose(gaussian_kl(mean, log_std, mean, log_std), torch.zeros(5), atol=1e-6)
    other_mean = mean + torch.randn(5, ACTION_DIM, generator=g) * 0.5
    other_log_std = log_std + 0.2
    ours = gaussian_kl(mean, log_std, other_mean, other_log_std)
    p = torch.distributions.Normal(mean, log_std.exp().expand_as(mean))
    q = torch.distributions.Normal(other_mean, other_log_std.exp().expand_as(other_mean))
    reference = torch.distributions.kl_divergence(p, q).sum(-1)
    assert (ours > 0).all()
    assert torch.allclose(ours, reference, atol=1e-5)
    # KL(p || q), not KL(q || p): the teacher is the first argument.
    assert not torch.allclose(ours, gaussian_kl(other_mean, other_log_std, mean, log_std), atol=1e-3)


def test_loss_goes_down_on_a_fixed_dataset():
    torch.manual_seed(0)
    student = StudentPolicy()
    obs, starts = _obs(3, 4), torch.zeros(3, 4, dtype=torch.bool)
    starts[:, 0] = True
    starts[1, 2] = True  # an episode ends inside the window
    g = torch.Generator().manual_seed(1)
    teacher_mean = torch.randn(3, 4, ACTION_DIM, generator=g) * 0.5
    teacher_log_std = torch.full((ACTION_DIM,), -0.5)
    optimizer = torch.optim.Adam(student.parameters(), lr=1e-3)
    losses = []
    for _ in range(30):
        loss, _ = window_loss(student, obs, starts, student.initial_state(3), teacher_mean,
                              teacher_log_std)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
    assert np.isfinite(losses).all()
    assert losses[-1] < 0.5 * losses[0], losses
    # The logged action error is the RMS of the mean actions' difference over the window.
    kl, rms, _ = window_terms(student, obs, starts, student.initial_state(3), teacher_mean,
                              teacher_log_std)
    with torch.no_grad():
        mean = student(obs, student.initial_state(3), starts).mean
    assert float(rms) == pytest.approx(float(((mean - teacher_mean) ** 2).mean().sqrt()), rel=1e-5)
    assert float(kl) == pytest.approx(losses[-1], rel=0.2)


def test_a_window_gradient_reaches_its_first_step_and_not_the_previous_window():
    torch.manual_seed(0)
    student = StudentPolicy()
    first, second = _obs(2, 3, seed=1), _obs(2, 3, seed=2)
    for obs in (first, second):
        obs["goal"].requires_grad_(True)
    labels = torch.zeros(2, 3, ACTION_DIM)
    log_std = torch.zeros(ACTION_DIM)
    # The previous window, run with gradients on, hands its GRU state to the next one.
    _, hidden = window_loss(student, first, torch.zeros(2, 3, dtype=torch.bool),
                            student.initial_state(2), labels, log_std)
    assert hidden.requires_grad
    loss, _ = window_loss(student, second, torch.zeros(2, 3, dtype=torch.bool), hidden, labels,
                          log_std)
    loss.backward()
    assert second["goal"].grad[:, 0].abs().sum() > 0  # the window's first step learns
    assert first["goal"].grad is None  # nothing flows into the window before


def test_beta_anneals_linearly_to_zero():
    cfg = DistillConfig(beta_start=0.5, beta_anneal_steps=100)
    assert [cfg.beta(s) for s in (0, 50, 100, 200)] == [0.5, 0.25, 0.0, 0.0]
    assert DistillConfig(beta_anneal_steps=0).beta(0) == 0.0


def test_distill_refuses_a_missing_teacher_naming_the_flag(tmp_path, capsys):
    out = tmp_path / "student"
    assert cli(["distill", "--run", str(tmp_path / "nope"), "--out", str(out),
                "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--run" in err[0] and "nope" in err[0]
    assert not out.exists()
    assert cli(["distill", "--out", str(out)]) == 2  # a new run needs a teacher
    assert "--run is required" in capsys.readouterr().err


# --- slow: a real teacher run and student envs --------------------------------------------------
@pytest.fixture(scope="module")
def teacher_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("dagger")
    run = root / "teacher"
    # A log-std away from the student's default 0, so the student's start at the teacher's shows.
    assert cli(["train", "--policy", "state", "--steps", "32", "--envs-per-worker", "2",
                "--rollout-steps", "16", "--set", "task.episode_steps=10", "--init-log-std",
                "-1.0", "--out", str(run), "--no-progress"]) == 0
    encoder = root / "encoder.pt"
    torch.manual_seed(0)
    save_encoder(encoder, make_policy_encoder("corn"))  # untrained: only with the weak flag
    return run, encoder


def _distill(teacher, encoder, out, steps, *extra):
    return cli(["distill", "--run", str(teacher), "--encoder", str(encoder),
                "--allow-weak-encoder", "--perception", "ground_truth", "--steps", str(steps),
                "--envs-per-worker", "2", "--window", "4", "--beta-start", "0.5",
                "--beta-anneal-steps", "64", "--log-every", "1", "--out", str(out), "--no-progress", *extra])


@pytest.mark.slow
def test_a_killed_distill_run_resumes_at_its_checkpoint_step(teacher_run, tmp_path, monkeypatch,
                                                             capsys):
    from corn_drake.rl.training import dagger

    teacher, encoder = teacher_run
    out = tmp_path / "student"
    # Killed during the 3rd window: the last checkpoint (every 2 windows of 8 steps) is step 16.
    real_update, calls = dagger.DaggerTrainer._update, []

    def dying_update(self, batch):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real_update(self, batch)

    monkeypatch.setattr(dagger.DaggerTrainer, "_update", dying_update)
    # The command line turns the interrupt into one line and exit 130 (cli.main).
    assert _distill(teacher, encoder, out, 40, "--checkpoint-every", "2") == 130
    assert "corn-drake distill: interrupted (SIGINT)" in capsys.readouterr().err
    monkeypatch.setattr(dagger.DaggerTrainer, "_update", real_update)
    state = load_checkpoint(out / "checkpoints" / "last.pt")
    assert state["global_step"] == 16 and state["update_index"] == 2
    assert state["beta"] == pytest.approx(0.5 * (1 - 16 / 64))
    capsys.readouterr()

    assert _distill(teacher, encoder, out, 40, "--checkpoint-every", "2") == 0
    assert "at step 16" in capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["global_step"] == 40 and metrics["updates"] == 5
    assert metrics["beta"] == pytest.approx(0.5 * (1 - 40 / 64))
    assert metrics["perception"] == "ground_truth"
    rows = metrics["history"]
    assert [r["step"] for r in rows] == sorted(r["step"] for r in rows) and rows[-1]["step"] == 40
    assert len(rows) == 5 and all(np.isfinite(r["loss"]) and r["loss"] >= 0 for r in rows)
    # The rows before the kill were checkpointed with it and kept: one per window.
    assert [r["update"] for r in rows] == [1, 2, 3, 4, 5]
    # 40 steps of 10-step episodes in 2 envs: episodes ended, with tracking errors recorded.
    assert sum(metrics["episodes_per_object"].values()) >= 2
    # StudentEnvs' tracking errors reach the episode stats (EnvBatch drops info otherwise).
    finished = load_checkpoint(out / "checkpoints" / "last.pt")["recent_episodes"]
    assert finished and all(0 <= e["mean_translation_error_m"] < 0.05 for e in finished)
    assert rows[-1]["tracking_translation_error_m"] == pytest.approx(
        np.mean([e["mean_translation_error_m"] for e in finished]))
    assert (out / "tb").is_dir() and (out / "plots" / "learning_curve.png").is_file()
    # What evaluation loads: the run's config and a student that acts.
    from corn_drake.rl.checkpoints import load_student_run

    cfg, student = load_student_run(out)
    assert cfg.total_steps == 40 and cfg.env.segmentation.mode == "ground_truth"
    mean, hidden = student.step({k: v[:, 0] for k, v in _obs(1, 1).items()})
    assert mean.shape == (1, ACTION_DIM) and torch.isfinite(mean).all()
    # The student's log-std started at the teacher's (-1) and moved by at most ~lr per update.
    assert student.log_std.detach().numpy() == pytest.approx(np.full(ACTION_DIM, -1.0), abs=0.01)
    assert all(0 <= r["action_rms_error"] < 2 for r in rows)
    # Up to the kill the run is its seed's: an uninterrupted run of those 2 windows learns the same.
    again = tmp_path / "again"
    assert _distill(teacher, encoder, again, 16) == 0
    rows_again = json.loads((again / "metrics.json").read_text())["history"]
    for key in ("loss", "teacher_action_fraction"):
        assert [r[key] for r in rows_again] == pytest.approx([r[key] for r in rows[:2]], rel=1e-5)
    capsys.readouterr()
    # The recorded config is the run's: a resume with another window is refused, naming it.
    assert _distill(teacher, encoder, out, 48, "--window", "8") == 2
    assert "--window" in capsys.readouterr().err
    # The teacher trained further (its weights changed): resuming would distil two teachers.
    weights = teacher / "checkpoints" / "last.pt"
    kept = weights.read_bytes()
    state = load_checkpoint(weights)
    state["global_step"] += 16
    try:
        torch.save(state, weights)
        assert _distill(teacher, encoder, out, 48) == 2
        err = capsys.readouterr().err
        assert "teacher_weights" in err and "mix" in err
    finally:
        weights.write_bytes(kept)
    assert json.loads((out / "metrics.json").read_text())["global_step"] == 40  # untouched


@pytest.mark.slow
def test_distill_refuses_a_student_run_as_teacher_and_a_teacher_without_encoder(
        teacher_run, tmp_path, capsys):
    teacher, encoder = teacher_run
    # A state teacher records no encoder: the student's must be given.
    assert cli(["distill", "--run", str(teacher), "--out", str(tmp_path / "s"),
                "--no-progress"]) == 2
    assert "--encoder" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()
    # A folder with a student's config.yaml is no teacher run.
    fake = tmp_path / "fake"
    fake.mkdir()
    from corn_drake.run_folders.config_file import write_run_config

    write_run_config(DistillConfig(teacher=str(teacher)), fake)
    assert cli(["distill", "--run", str(fake), "--encoder", str(encoder), "--out",
                str(tmp_path / "s2"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "--run" in err and "not a trained teacher run" in err


@pytest.mark.slow
def test_a_run_whose_config_was_edited_after_training_is_refused(teacher_run, tmp_path, capsys):
    """The checkpoint knows the env it was trained on: a config.yaml edited afterwards cannot
    make evaluate (or distill, or ship) say it measured what the weights were not trained on."""
    import shutil

    teacher, _ = teacher_run
    run = tmp_path / "teacher"
    shutil.copytree(teacher, run)
    config = run / "config.yaml"
    text = config.read_text()
    assert "episode_steps: 10\n" in text
    config.write_text(text.replace("episode_steps: 10\n", "episode_steps: 40\n"))
    report = tmp_path / "r.json"
    assert cli(["evaluate", "--run", str(run), "--episodes", "1", "--record", "0",
                "--no-progress", "--report", str(report)]) == 2
    err = capsys.readouterr().err
    assert "config.yaml" in err and "edited after training" in err and not report.exists()
    config.write_text(text)  # restored: it loads again
    assert cli(["evaluate", "--run", str(run), "--episodes", "1", "--record", "0",
                "--no-progress", "--report", str(report)]) == 0
