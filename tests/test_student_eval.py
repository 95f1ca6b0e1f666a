"""The student's evaluation: StudentPolicySystem acts as the training path does with its GRU state
in the context (reset per episode), `evaluate` on a distill run folder reports perception and
pose tracking, bad input is named, and `bench student` reports its ratio.

The student is randomly initialised (its actions only have to be the network's, not good ones);
the distill run folder is written the way `corn-drake distill` writes one (config.yaml through
write_run_config, checkpoints/last.pt through save_checkpoint with kind "student")."""

import json

import numpy as np
import pytest
import torch

from corn_drake.cli import main
from corn_drake.config.training import DistillConfig
from corn_drake.contract import STUDENT_OBS_KEYS
from corn_drake.config.plumbing.diagram_files import load_student_config
from corn_drake.storage.checkpoint_files import load_checkpoint, save_checkpoint
from corn_drake.nn.student import StudentPolicy
from corn_drake.nn.threads import torch_threads
from corn_drake.rl.envs.student_env import StudentEnv
from corn_drake.run_folders.config_file import write_run_config
from corn_drake.systems.control.ik import ActionScaling
from tests.fixtures import one_error_line


def _student(seed: int = 0) -> StudentPolicy:
    torch.manual_seed(seed)
    student = StudentPolicy()
    with torch.no_grad():  # a recurrence that matters: h_t moves the action visibly
        for p in student.gru.parameters():
            p.mul_(3.0)
    return student.eval()


def _tensors(obs: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
    return {k: torch.from_numpy(np.asarray(obs[k]))[None] for k in STUDENT_OBS_KEYS}


def _latched(env) -> np.ndarray:
    """The physical action ActionToJointTargets latched at the last policy step."""
    ik = env.handles.teacher.ik
    return ik.GetOutputPort("previous_action").Eval(ik.GetMyContextFromRoot(env.context))


def _policy_state(env):
    policy = env.handles.policy
    ctx = policy.GetMyContextFromRoot(env.context)
    return policy, ctx, policy.hidden_state(ctx)


@pytest.fixture(scope="module")
def student():
    return _student()


@pytest.fixture(scope="module")
def envs(student):
    """(the evaluation env: the student inside the diagram; the training path's env: actions
    given through the gymnasium API), both on the default geometric chain."""
    cfg = load_student_config()
    return StudentEnv(cfg, student=student), StudentEnv(cfg)


def test_evaluation_system_acts_as_the_training_path_step_by_step(student, envs):
    eval_env, train_env = envs
    assert eval_env.policy_in_diagram and not train_env.policy_in_diagram
    scaling = ActionScaling(eval_env.teacher_cfg.controller)
    obs_e, _ = eval_env.reset(seed=5)
    obs_t, _ = train_env.reset(seed=5)
    hidden = None  # the training path's state at an episode start (DAgger: starts -> zeros)
    for t in range(4):
        # Same state on both paths: the student sees the same observation.
        for key in STUDENT_OBS_KEYS:
            np.testing.assert_array_equal(obs_e["student"][key], obs_t["student"][key],
                                          err_msg=f"step {t} {key}")
        policy, ctx, h_in_context = _policy_state(eval_env)
        expected_h = student.initial_state(1) if hidden is None else hidden
        torch.testing.assert_close(h_in_context, expected_h, rtol=0, atol=1e-7)
        # At the system's one torch thread (student_policy.py): the same computation as its
        # step, not just a close one (another thread count may split a reduction, and round,
        # differently), so the 1e-9 checks on the state after contact hold on any machine.
        with torch_threads(1):
            mean, next_hidden = student.step(_tensors(obs_t["student"]), hidden)
        action = mean.clamp(-1, 1)[0].numpy().astype(np.float64)
        np.testing.assert_allclose(policy.GetOutputPort("action").Eval(ctx), action, atol=1e-6)
        # The test can tell h_t from h_{t+1}: acting on the next state would give another action.
        wrong = student.step(_tensors(obs_t["student"]), next_hidden)[0].clamp(-1, 1)[0].numpy()
        assert np.abs(wrong - action).max() > 1e-3, t

        obs_e = eval_env.step()[0]
        obs_t = train_env.step(action)[0]
        # The action the controller latched is the training path's a_t (physical units) ...
        np.testing.assert_allclose(_latched(eval_env), scaling.to_physical(action), atol=1e-6)
        np.testing.assert_allclose(_latched(eval_env), _latched(train_env), atol=1e-9)
        # ... and the context now holds h_{t+1}.
        torch.testing.assert_close(_policy_state(eval_env)[2], next_hidden, rtol=0, atol=1e-6)
        np.testing.assert_allclose(
            eval_env.scene.plant.GetPositionsAndVelocities(eval_env.plant_context),
            train_env.scene.plant.GetPositionsAndVelocities(train_env.plant_context), atol=1e-9)
        hidden = next_hidden
    assert hidden.abs().max() > 0.05  # the carried state was not trivially zero


def test_a_second_episode_starts_from_the_initial_hidden_state(student, envs):
    eval_env, _ = envs
    eval_env.reset(seed=1)
    for _ in range(3):
        eval_env.step()
    assert _policy_state(eval_env)[2].abs().max() > 0.05  # the first episode left memory
    obs, _ = eval_env.reset(seed=2)
    policy, ctx, hidden = _policy_state(eval_env)
    assert torch.equal(hidden, student.initial_state(1))
    fresh, _ = student.step(_tensors(obs["student"]))
    np.testing.assert_allclose(policy.GetOutputPort("action").Eval(ctx),
                               fresh.clamp(-1, 1)[0].numpy(), atol=1e-6)
    eval_env.step()
    np.testing.assert_allclose(_latched(eval_env), ActionScaling(
        eval_env.teacher_cfg.controller).to_physical(fresh.clamp(-1, 1)[0].numpy()), atol=1e-6)


def test_stochastic_student_samples_around_its_mean_with_the_diagrams_noise(student):
    cfg = load_student_config()
    cfg.segmentation.mode = "ground_truth"
    env = StudentEnv(cfg, student=student, stochastic_policy=True)
    assert env.diagram.HasSubsystemNamed("policy_noise") and env.handles.policy.stochastic
    obs, _ = env.reset(seed=3)
    policy, ctx, _ = _policy_state(env)
    noise = policy.GetInputPort("unit_noise").Eval(ctx)
    mean, _ = student.step(_tensors(obs["student"]))
    expected = np.clip(mean[0].numpy() + student.log_std.detach().exp().numpy() * noise, -1, 1)
    np.testing.assert_allclose(policy.GetOutputPort("action").Eval(ctx), expected, atol=1e-6)
    assert np.abs(noise).max() > 0.1
    with pytest.raises(ValueError, match="needs a student"):
        StudentEnv(cfg, stochastic_policy=True)
    with pytest.raises(ValueError, match="eval mode"):
        StudentEnv(cfg, student=StudentPolicy())  # train mode: dropout would randomise it


# --- `corn-drake evaluate` on a distill run ---------------------------------------------------
def write_distill_run(folder, episode_steps: int = 3, trained_perception: str = "ground_truth"):
    """A distill run folder holding a randomly initialised student, as `distill` saves one."""
    env = load_student_config()
    env.teacher.task.episode_steps = episode_steps
    env.segmentation.mode = trained_perception
    write_run_config(DistillConfig(teacher="runs/T", encoder="encoder.pt", env=env), folder)
    save_checkpoint(folder / "checkpoints" / "last.pt",
                    {"kind": "student", "student": _student(1).state_dict(), "global_step": 96})
    return folder


def test_evaluate_a_distill_run_reports_perception_and_tracking(tmp_path, capsys):
    run = write_distill_run(tmp_path / "student")
    report = tmp_path / "eval_student.json"
    assert main(["evaluate", "--run", str(run), "--episodes", "2", "--record", "0",
                 "--report", str(report)]) == 0
    data = json.loads(report.read_text())
    for key in ("success_rate", "balanced_success_rate", "per_object", "episodes", "task",
                "action_step", "mean_episode_length", "overrides", "split", "actions"):
        assert key in data, key
    assert data["policy"] == "student" and data["actions"] == "mean"
    # Trained with ground truth, evaluated through the full chain by default.
    assert data["perception"] == "geometric" and data["trained_perception"] == "ground_truth"
    assert data["observation_noise"]["cloud_noise_std"] > 0
    rows = data["episodes"]
    assert len(rows) == 2 and all(1 <= r["steps"] <= 3 for r in rows)
    tracking = data["tracking"]
    assert tracking["steps"] == sum(r["steps"] for r in rows)
    for key in ("translation_error_m", "rotation_error_deg"):
        stats = tracking[key]
        assert 0 <= stats["median"] <= stats["max"] and 0 <= stats["mean"] <= stats["max"]
        # The overall maximum is the largest episode maximum.
        assert stats["max"] == max(r["tracking"][key]["max"] for r in rows)
    assert tracking["translation_error_m"]["max"] < 0.02  # a few steps of a tracked box
    assert 0 <= tracking["ok_fraction"] <= 1
    assert "geometric" in capsys.readouterr().out

    assert main(["evaluate", "--run", str(run), "--episodes", "1", "--record", "0",
                 "--perception", "ground_truth", "--set", "task.episode_steps=2",
                 "--report", str(report), "--overwrite"]) == 0  # other settings: afresh
    data = json.loads(report.read_text())
    assert data["perception"] == "ground_truth" and data["episodes"][0]["steps"] <= 2
    assert [o["key"] for o in data["overrides"]] == ["env.task.episode_steps"]
    assert data["tracking"]["steps"] == data["episodes"][0]["steps"]


def test_ship_a_student_run_evaluates_as_the_run(tmp_path, capsys):
    """`ship` of a distill run: the weights folder holds the student alone (its weights carry its
    encoder), evaluates to the same report as the run, and its card names the perception chain."""
    from tests.fixtures import write_loadable_library

    library = write_loadable_library(tmp_path / "lib", 1, num_unseen=1)
    run = write_distill_run(tmp_path / "student", episode_steps=2)
    args = ["--objects", str(library), "--split", "unseen", "--episodes", "1", "--record", "0"]
    report = tmp_path / "eval_run.json"
    assert main(["evaluate", "--run", str(run), *args, "--report", str(report)]) == 0
    out = tmp_path / "weights" / "student"
    assert main(["ship", "--run", str(run), "--report", str(report), "--library-command",
                 f"corn-drake objects --num-objects 2 --seed 0 --split unseen --out {library}",
                 "--out", str(out)]) == 0
    card = json.loads((out / "card.json").read_text())
    assert card["policy"] == "student" and card["perception"] == "geometric"
    assert card["trained_perception"] == "ground_truth" and card["teacher"] == "runs/T"
    assert card["env_steps"] == 96 and card["episodes"] == 1 and card["cameras"] == "fixed"
    assert card["encoder"]["file"] is None  # the student's weights hold its encoder
    assert sorted(card["bytes"]) == ["checkpoints/last.pt", "config.yaml"]
    assert set(load_checkpoint(out / "checkpoints" / "last.pt")) == {"kind", "student",
                                                                     "global_step"}
    again = tmp_path / "eval_shipped.json"
    assert main(["evaluate", "--run", str(out), *args, "--report", str(again)]) == 0
    first, second = (json.loads(p.read_text()) for p in (report, again))
    assert [r["success"] for r in second["episodes"]] == [r["success"] for r in first["episodes"]]
    assert second["episodes"][0]["position_error"] == pytest.approx(
        first["episodes"][0]["position_error"], abs=1e-6)
    # A student's report without a perception chain is refused, naming it.
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps({k: v for k, v in first.items() if k != "perception"}))
    capsys.readouterr()
    assert main(["ship", "--run", str(run), "--report", str(bare), "--library-command",
                 f"corn-drake objects --out {library}", "--out", str(tmp_path / "w2")]) == 2
    assert "perception" in capsys.readouterr().err
    assert not (tmp_path / "w2").exists()
    # A run whose weights are gone is refused before OUT is made.
    (run / "checkpoints" / "last.pt").unlink()
    assert main(["ship", "--run", str(run), "--report", str(report), "--library-command",
                 f"corn-drake objects --out {library}", "--out", str(tmp_path / "w3")]) != 0
    assert "checkpoint" in capsys.readouterr().err and not (tmp_path / "w3").exists()


def test_evaluate_names_a_run_of_neither_kind_and_perception_without_a_student(tmp_path, capsys):
    from corn_drake.config.training import TrainConfig

    report = tmp_path / "r.json"
    odd = tmp_path / "odd"
    odd.mkdir()
    (odd / "config.yaml").write_text("steps: 3\nmodel: corn\n")  # e.g. a pretraining config
    assert main(["evaluate", "--run", str(odd), "--report", str(report)]) == 2
    one_error_line(capsys, f"--run {odd}", "neither", "train", "distill")
    teacher = tmp_path / "teacher"
    write_run_config(TrainConfig(), teacher)
    assert main(["evaluate", "--run", str(teacher), "--perception", "ground_truth",
                 "--report", str(report)]) == 2
    one_error_line(capsys, "--perception ground_truth", str(teacher), "teacher run")
    assert main(["evaluate", "--run", "scripted", "--perception", "geometric",
                 "--report", str(report)]) == 2
    one_error_line(capsys, "--perception geometric", "reference controller")
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["evaluate", "--run", str(empty), "--report", str(report)]) == 2
    one_error_line(capsys, str(empty / "config.yaml"), "distill")
    # A distill config without its student checkpoint.
    student = write_distill_run(tmp_path / "student")
    (student / "checkpoints" / "last.pt").unlink()
    assert main(["evaluate", "--run", str(student), "--report", str(report)]) == 2
    one_error_line(capsys, "no student checkpoint", str(student))
    assert not report.exists()


def test_bench_student_reports_its_ratio_to_the_teacher_env(tmp_path):
    report = tmp_path / "bench_student.json"
    assert main(["bench", "student", "--steps", "3", "--repeats", "1",
                 "--report", str(report)]) == 0
    data = json.loads(report.read_text())
    results = data["results"]
    assert data["benchmark"] == "student" and "cpu_count" in data["machine"]
    for key in ("student_env_steps_per_s", "teacher_env_steps_per_s",
                "student_policy_in_loop_steps_per_s"):
        assert results[key] > 0, key
    assert results["student_to_teacher_ratio"] == pytest.approx(
        results["student_env_steps_per_s"] / results["teacher_env_steps_per_s"])
    assert 0 < results["student_to_teacher_ratio"]
    assert results["segmentation"] == "geometric" and results["steps"] == 3
    assert results["object"] and results["cameras"].startswith("3 x ")
