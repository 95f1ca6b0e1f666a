"""The contact-primitive policy through the command line: `train --policy primitive` refuses what
does not apply to it, a killed run resumes where its checkpoint left it, `ship` makes a weights
folder `evaluate` and `gallery` read, and `bench primitive` writes its report.

Runs are tiny (the task's box, 2 envs, a few dozen primitives) and in this process; the policy
is barely trained, so the tests check what the commands write and that the shipped folder
behaves as the run, not how well it pushes.
"""

import collections
import json

import pytest

from corn_drake.cli import main
from corn_drake.package_data import data_dir
from corn_drake.rl.training.primitive_trainer import PrimitiveTrainer
from corn_drake.rl.primitive.replay import ReplayBuffer
from corn_drake.storage.checkpoint_files import load_checkpoint
from tests.fixtures import one_error_line

WEIGHTS = data_dir("models") / "weights"
ENCODER = str(WEIGHTS / "push_corn" / "encoder.pt")
# The smallest run that learns at all: 8 random primitives fill the replay, then TD3 updates.
TINY = ["--task", "push", "--encoder", ENCODER, "--envs-per-worker", "2", "--no-progress",
        "--set", "random_steps=8", "--set", "learning_starts=8", "--set", "log_every=8"]


def _train(out, steps: int, *extra: str) -> int:
    return main(["train", "--policy", "primitive", *TINY, "--steps", str(steps), "--out",
                 str(out), *extra])


def _checkpoint(run) -> dict:
    return load_checkpoint(run / "checkpoints" / "last.pt", fallback=False)


# --- what train refuses ------------------------------------------------------------------------
@pytest.mark.parametrize("flag, value", [("--rollout-steps", "8"), ("--minibatches", "2"),
                                         ("--init-log-std", "-0.5")])
def test_train_primitive_refuses_a_ppo_flag_naming_it(tmp_path, capsys, flag, value):
    out = tmp_path / "run"
    assert _train(out, 16, flag, value) == 2
    one_error_line(capsys, flag, "PPO")
    assert not (out / "config.yaml").exists()


def test_train_primitive_refuses_to_start_without_an_encoder(tmp_path, capsys):
    out = tmp_path / "run"
    argv = [a for a in TINY if a not in ("--encoder", ENCODER)]
    assert main(["train", "--policy", "primitive", *argv, "--steps", "16", "--out", str(out)]) == 2
    one_error_line(capsys, "--encoder")
    assert not (out / "config.yaml").exists()


# --- a killed run resumes ----------------------------------------------------------------------
def test_a_killed_primitive_run_resumes_at_its_checkpoint(tmp_path, capsys, monkeypatch):
    """A run of 24 primitives killed (Ctrl-C) at primitive 20 with checkpoints every 8: last.pt
    holds step 16 and its replay file 16 transitions. Resumed with --steps 32, the run starts
    from that checkpoint: the step goes 16 -> 32, the replay holds all 32 transitions (16
    restored + 16 new: a replay started afresh would hold 16), and the metrics history carries
    on from the rows saved before the kill."""
    run = tmp_path / "run"
    round_ = PrimitiveTrainer._round

    def killed_at_20(self, *args):
        if self.global_step >= 20:
            raise KeyboardInterrupt
        return round_(self, *args)

    monkeypatch.setattr(PrimitiveTrainer, "_round", killed_at_20)
    assert _train(run, 24, "--set", "checkpoint_every=8") == 130
    assert "interrupted (SIGINT)" in capsys.readouterr().err
    before = _checkpoint(run)
    assert before["global_step"] == 16 and before["replay_file"] == "replay_000000016.npz"
    assert len(ReplayBuffer.load(run / "checkpoints" / before["replay_file"])) == 16
    assert [row["step"] for row in before["history"]] == [8, 16]
    assert not (run / "metrics.json").exists()  # written when a run ends, not at a kill

    # A replay write that a kill -9 cut short leaves its temporary file: the resume removes it.
    stray = run / "checkpoints" / ".replay_000000024.npz.k1ll3d.tmp"
    stray.write_bytes(b"half a replay")
    monkeypatch.setattr(PrimitiveTrainer, "_round", round_)
    # The same command that started it resumes it (as a PPO run does): its --encoder names the
    # file the run copied to encoder.pt, another spelling of the same encoder.
    assert _train(run, 32, "--set", "checkpoint_every=8") == 0
    assert f"resume {run}" in capsys.readouterr().out
    after = _checkpoint(run)
    assert after["global_step"] == 32 and after["replay_file"] == "replay_000000032.npz"
    assert len(ReplayBuffer.load(run / "checkpoints" / after["replay_file"])) == 32
    assert after["episodes"] >= before["episodes"]
    assert after["learner"]["updates"] > before["learner"]["updates"]
    history = json.loads((run / "metrics.json").read_text())["history"]
    assert [row["step"] for row in history] == [8, 16, 24, 32]
    assert history[:2] == before["history"]  # the rows from before the kill, as saved
    assert history[-1]["replay"] == 32
    # Another encoder's bytes are another encoder, however it is named: refused in one line.
    other = tmp_path / "encoder.pt"
    other.write_bytes(b"not the run's encoder")
    assert _train(run, 40, "--encoder", str(other)) == 2
    one_error_line(capsys, "encoder")
    assert _checkpoint(run)["global_step"] == 32
    assert not stray.exists()
    # A step count between whole rounds (2 envs: 2 primitives a round) is trained as the next
    # whole round, and said.
    assert _train(run, 33, "--set", "checkpoint_every=8") == 0
    assert "--steps 33 trained as 34" in capsys.readouterr().out
    assert _checkpoint(run)["global_step"] == 34


def test_a_corrupt_newest_replay_resumes_from_the_previous_checkpoint_and_replay(tmp_path, capsys):
    run = tmp_path / "run"
    assert _train(run, 16, "--set", "checkpoint_every=8") == 0
    newest = run / "checkpoints" / _checkpoint(run)["replay_file"]
    previous = load_checkpoint(run / "checkpoints" / "prev.pt", fallback=False)
    assert previous["global_step"] == 8  # the pair before: kept through the run's last save
    kept = len(ReplayBuffer.load(run / "checkpoints" / previous["replay_file"]))
    newest.write_bytes(newest.read_bytes()[:100])  # cut short, as by a full disk or a copy
    capsys.readouterr()
    assert _train(run, 24, "--set", "checkpoint_every=8") == 0
    err = capsys.readouterr().err
    assert "resuming from the previous checkpoint" in err and "(step 8)" in err
    after = _checkpoint(run)
    assert after["global_step"] == 24
    # Step 8's transitions and those of the 16 primitives after it (hindsight copies add more).
    assert len(ReplayBuffer.load(run / "checkpoints" / after["replay_file"])) >= kept + 16


# --- ship, evaluate and gallery ----------------------------------------------------------------
@pytest.fixture(scope="module")
def shipped(tmp_path_factory):
    """A tiny trained run, its evaluation on a two-object library's unseen object, and the
    folder `ship` made of it: (run, library, the run's report, shipped folder, ship's output)."""
    import contextlib
    import io

    from tests.fixtures import write_loadable_library

    root = tmp_path_factory.mktemp("primitive_ship")
    run, library = root / "run", write_loadable_library(root / "lib", 1, num_unseen=1)
    assert _train(run, 24) == 0
    report = root / "eval_run.json"
    assert main(["evaluate", "--run", str(run), "--objects", str(library), "--split", "unseen",
                 "--episodes", "2", "--record", "0", "--no-progress", "--report",
                 str(report)]) == 0
    out, printed = root / "weights" / "push_primitive", io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["ship", "--run", str(run), "--report", str(report), "--library-command",
                     f"corn-drake objects --num-objects 2 --seed 0 --split unseen --out {library}",
                     "--train-command", "corn-drake train --policy primitive ...",
                     "--out", str(out)]) == 0
    return run, library, json.loads(report.read_text()), out, printed.getvalue()


def _check_report(report: dict, episodes: int) -> None:
    assert report["policy"] == "primitive" and report["env_steps_unit"] == "primitives"
    rows = report["episodes"]
    assert len(rows) == episodes and all("failure" in row for row in rows)
    counts = report["failure_counts"]
    assert sum(counts.values()) == episodes
    for category, n in collections.Counter(row["failure"] for row in rows).items():
        assert counts[category] == n, (category, counts)


def test_a_shipped_primitive_folder_holds_what_evaluate_reads_and_evaluates_as_the_run(
        shipped, tmp_path, capsys):
    run, library, report, out, printed = shipped
    _check_report(report, 2)
    assert report["env_steps"] == 24
    assert "24 primitives" in printed
    card = json.loads((out / "card.json").read_text())
    teacher_card = json.loads((WEIGHTS / "push_corn" / "card.json").read_text())
    assert set(teacher_card) <= set(card), set(teacher_card) - set(card)  # a card like the others
    assert card["policy"] == "primitive" and card["env_steps"] == 24
    assert card["location_count"] == 16
    assert card["env_steps_unit"] == "primitives" and card["episodes"] == 2
    assert card["success_rate"] == report["success_rate"] and card["source_run"] == str(run)
    assert card["encoder"]["file"] == "encoder.pt" and card["encoder"]["kind"] == "corn"
    # What evaluate needs, and the learning curve; the replay files stay with the run.
    assert sorted(card["bytes"]) == ["checkpoints/last.pt", "config.yaml", "encoder.pt",
                                     "training_history.json"]
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()) == \
        ["card.json", "checkpoints/last.pt", "config.yaml", "encoder.pt", "training_history.json"]
    assert list((run / "checkpoints").glob("replay_*.npz"))  # the run had one to leave behind
    assert set(load_checkpoint(out / "checkpoints" / "last.pt")) == {"agent", "global_step"}

    again = tmp_path / "eval_shipped.json"
    assert main(["evaluate", "--run", str(out), "--objects", str(library), "--split", "unseen",
                 "--episodes", "2", "--record", "0", "--no-progress", "--report",
                 str(again)]) == 0
    second = json.loads(again.read_text())
    _check_report(second, 2)
    assert second["run"] == str(out) and second["env_steps"] == 24
    # The same weights, objects and seeds: the same episodes.
    for mine, theirs in zip(second["episodes"], report["episodes"]):
        assert (mine["object"], mine["seed"], mine["success"], mine["steps"]) == \
            (theirs["object"], theirs["seed"], theirs["success"], theirs["steps"])
        assert mine["position_error"] == pytest.approx(theirs["position_error"], abs=1e-6)

    capsys.readouterr()
    assert main(["evaluate", "--run", str(out), "--attention", "--report",
                 str(tmp_path / "no.json")]) == 2
    one_error_line(capsys, "--attention", "contact-primitive", "Meshcat")
    assert not (tmp_path / "no.json").exists()


def test_evaluate_set_reaches_a_primitive_runs_executor_settings(shipped, tmp_path, capsys):
    """--set primitive.* changes the policy's own executor settings (its config's `primitive:`),
    is recorded as an override, and is range-checked; other runs keep env.* only."""
    run, library, report, _, _ = shipped
    one = tmp_path / "one_primitive.json"
    assert main(["evaluate", "--run", str(run), "--objects", str(library), "--split", "unseen",
                 "--episodes", "2", "--record", "0", "--no-progress", "--set",
                 "primitive.max_primitives=1", "--report", str(one)]) == 0
    changed = json.loads(one.read_text())
    assert changed["overrides"] == [{"key": "primitive.max_primitives", "old": 10, "new": 1}]
    # One primitive per episode: never more policy periods than the run's own episodes, and
    # fewer wherever the run's own episode took more than one primitive.
    ticks = {mine["seed"]: (mine["steps"], theirs["steps"])
             for mine, theirs in zip(changed["episodes"], report["episodes"])}
    assert all(a <= b for a, b in ticks.values()) and any(a < b for a, b in ticks.values()), ticks
    capsys.readouterr()
    assert main(["evaluate", "--run", str(run), "--set", "primitive.push_steps=0", "--report",
                 str(tmp_path / "no.json")]) == 2
    one_error_line(capsys, "primitive.push_steps", "[1, 100]")
    assert main(["evaluate", "--run", str(run), "--set", "gamma=0.5", "--report",
                 str(tmp_path / "no.json")]) == 2
    one_error_line(capsys, "gamma=0.5", "only env.* and primitive.*")
    assert main(["evaluate", "--run", "scripted", "--set", "primitive.push_steps=2", "--report",
                 str(tmp_path / "no.json")]) == 2
    one_error_line(capsys, "primitive.push_steps=2", "unknown key 'primitive'")
    assert not (tmp_path / "no.json").exists()


def test_the_gallery_shows_a_shipped_primitive_policys_episode(shipped, tmp_path):
    """The stills come from evaluate's own episode of the object and seed (the report's first),
    the cloud painted by the policy's location scores."""
    _, library, report, out, _ = shipped
    first = report["episodes"][0]
    gallery = tmp_path / "gallery"
    assert main(["gallery", "--run", str(out), "--objects", str(library), "--ids",
                 first["object"], "--out", str(gallery), "--animate", "--frames", "3",
                 "--frame-height", "48"]) == 0
    data = json.loads((gallery / "gallery.json").read_text())
    assert data["policy"] == "primitive" and data["painted"] == "location scores"
    entry = data["episodes"][0]
    assert (entry["seed"], entry["success"], entry["steps"]) == \
        (first["seed"], first["success"], first["steps"])
    assert entry["position_error"] == pytest.approx(first["position_error"], abs=1e-6)
    assert entry["primitives"] >= 1 and entry["steps_shown"] == [0, first["steps"] // 2,
                                                                 first["steps"]]
    # Whether it ended at rest, as the report's row says (a success that tumbles through the
    # goal is no picture of success).
    from corn_drake.config.primitive import at_rest

    assert entry["ended_at_rest"] == at_rest(entry["end_speed"]) and data["overrides"] == []
    # The object's points painted in every still it is in (an episode that ends off the table
    # ends with the object out of the camera's view).
    painted = entry["points_painted"][:-1] if first["out_of_workspace"] else \
        entry["points_painted"]
    assert min(painted) > 10
    assert (gallery / entry["image"]).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The same episode as a GIF: its first, middle and last step, 64 x 48.
    from PIL import Image

    assert entry["animation_steps"] == [0, first["steps"] // 2, first["steps"]]
    with Image.open(gallery / entry["animation"]) as gif:
        assert (gif.format, gif.n_frames, gif.size) == ("GIF", 3, (64, 48))
    # A gallery of the same run again, without --animate: its earlier GIF goes, the folder
    # shows one gallery; another run's gallery there is refused (--overwrite replaces it).
    assert main(["gallery", "--run", str(out), "--objects", str(library), "--ids",
                 first["object"], "--out", str(gallery)]) == 0
    assert not (gallery / entry["animation"]).exists() and (gallery / entry["image"]).exists()
    data["run"] = "runs/someone_elses"
    (gallery / "gallery.json").write_text(json.dumps(data))
    argv = ["gallery", "--run", str(out), "--objects", str(library), "--ids", first["object"],
            "--out", str(gallery)]
    assert main(argv) == 2
    assert json.loads((gallery / "gallery.json").read_text())["run"] == "runs/someone_elses"
    assert main([*argv, "--overwrite"]) == 0
    # --set as evaluate takes it: under the at-rest rule a success ends with the object still.
    assert main([*argv, "--overwrite", "--set", "primitive.success_at_rest=true"]) == 0
    rested = json.loads((gallery / "gallery.json").read_text())
    assert rested["overrides"] == [{"key": "primitive.success_at_rest", "old": False,
                                    "new": True}]
    assert all(e["ended_at_rest"] for e in rested["episodes"] if e["success"])


# An outcome model file's learning curve (rl/primitive/outcome/model.fit_network's rows).
FIT_HISTORY = [{"update": 100, "huber_loss": 0.04}, {"update": 150, "huber_loss": 0.03}]


def test_a_run_that_chooses_by_an_outcome_model_evaluates_and_ships_with_it(
        shipped, tmp_path, capsys):
    """A run folder written by write_outcome_run (config chooser: outcome_model) chooses by its
    model in evaluate, ships its model with its card, and the shipped folder replays its
    episodes; a missing model file or a training run with that chooser is refused by name."""
    import shutil

    import torch

    from corn_drake.rl.primitive.outcome.model import MODEL_FILE, OutcomeModel
    from corn_drake.rl.primitive.outcome.run_folder import outcome_run_config, write_outcome_run

    run, library, critic_report, shipped_folder, _ = shipped
    torch.manual_seed(1)
    model = OutcomeModel(38)
    torch.nn.init.normal_(model.net[-1].weight, std=0.1)  # the fresh model says "no motion"
    outcome = tmp_path / "runs" / "outcome"
    write_outcome_run(run, outcome_run_config(run, None, ["primitive.max_primitives=3"]),
                      model.eval(), False, {"states": 7, "fit_history": FIT_HISTORY}, outcome)
    assert sorted(p.relative_to(outcome).as_posix() for p in outcome.rglob("*")
                  if p.is_file()) == ["checkpoints/last.pt", "config.yaml", MODEL_FILE]
    report_path = tmp_path / "eval_outcome.json"
    args = ["--objects", str(library), "--split", "unseen", "--episodes", "2", "--record", "0",
            "--no-progress"]
    assert main(["evaluate", "--run", str(outcome), *args, "--report", str(report_path)]) == 0
    report = json.loads(report_path.read_text())
    _check_report(report, 2)
    assert critic_report["chooser"] == "critic" and report["chooser"] == "outcome_model"
    assert report["outcome_model"]["states"] == 7 and report["outcome_model"]["bank_motions"] == 32
    assert "fit_history" not in report["outcome_model"]  # the curve goes to the shipped folder
    assert not report.get("overrides")  # the run's own settings (3 primitives) are its config's

    from corn_drake.rl.primitive.agent import load_primitive_run

    # Shipped alone its folder holds a copy of the actor and critic; beside the shipped folder
    # of the run that proposes its motions, it names that folder instead.
    alone, beside = tmp_path / "weights" / "outcome_primitive", \
        shipped_folder.parent / "outcome_primitive"
    for out in (alone, beside):
        assert main(["ship", "--run", str(outcome), "--report", str(report_path),
                     "--library-command",
                     f"corn-drake objects --num-objects 2 --seed 0 --split unseen --out {library}",
                     "--train-command", "corn-drake fit-outcome ...", "--out", str(out)]) == 0
        card = json.loads((out / "card.json").read_text())
        shipped_cfg, shipped_agent, _ = load_primitive_run(out)
        assert shipped_cfg.primitive.max_primitives == 3
        assert shipped_agent.outcome_chooser is not None
        assert card["chooser"] == "outcome_model" and card["outcome_model"]["file"] == MODEL_FILE
        assert MODEL_FILE in card["bytes"]
        # Its learning curve is its model's fit, not the proposing run's TD3 history.
        assert json.loads((out / "training_history.json").read_text())["history"] == FIT_HISTORY
        assert "fit_history" not in card["outcome_model"]
        assert ("checkpoints/last.pt" in card["bytes"]) == (out == alone), card["bytes"]
        assert shipped_cfg.agent_weights == ("" if out == alone else "../push_primitive")
        again = tmp_path / f"eval_shipped_{out == alone}.json"  # each folder's own report
        assert main(["evaluate", "--run", str(out), *args, "--report", str(again)]) == 0
        for mine, theirs in zip(json.loads(again.read_text())["episodes"], report["episodes"]):
            assert (mine["seed"], mine["success"], mine["steps"]) == \
                (theirs["seed"], theirs["success"], theirs["steps"])

    # A shipped outcome folder (its actor and critic named, not held) proposes for a new one.
    again_run = tmp_path / "runs" / "from_shipped"
    write_outcome_run(beside, outcome_run_config(beside, None, []), model.eval(), False, {},
                      again_run)
    again_cfg, again_agent, _ = load_primitive_run(again_run)
    assert again_cfg.agent_weights == "" and (again_run / "checkpoints" / "last.pt").is_file()
    assert again_agent.outcome_chooser is not None

    # The retired outcome.* settings (pessimism, tilt veto and blend) are refused in one line.
    capsys.readouterr()
    assert main(["evaluate", "--run", str(outcome), *args, "--report",
                 str(tmp_path / "no.json"), "--set", "outcome.pessimism=1"]) == 2
    one_error_line(capsys, "outcome was retired", "0.340 against 0.345")

    capsys.readouterr()
    broken = tmp_path / "broken"
    shutil.copytree(outcome, broken)
    (broken / MODEL_FILE).unlink()
    assert main(["evaluate", "--run", str(broken), *args, "--report",
                 str(tmp_path / "no.json")]) == 2
    one_error_line(capsys, "outcome_model.pt", "no outcome model")
    assert _train(tmp_path / "no_run", 16, "--set", "chooser=outcome_model") == 2
    one_error_line(capsys, "chooser 'outcome_model'", "corn-drake fit-outcome")
    assert _train(tmp_path / "no_run", 16, "--set", "chooser=oracle") == 2
    one_error_line(capsys, "chooser must be one of critic, outcome_model", "'oracle'")
    assert _train(tmp_path / "no_run", 16, "--set", "agent_weights=../push_primitive") == 2
    one_error_line(capsys, "agent_weights", "its own actor and critic")
    assert not (tmp_path / "no.json").exists() and not (tmp_path / "no_run").exists()


# --- bench -------------------------------------------------------------------------------------
def test_bench_primitive_reports_its_rates_against_the_dense_teacher(tmp_path):
    path = tmp_path / "bench.json"
    assert main(["bench", "primitive", "--report", str(path), "--decisions", "2",
                 "--dense-steps", "2", "--updates", "2", "--warmup", "0",
                 "--batch-size", "4"]) == 0
    report = json.loads(path.read_text())
    assert report["benchmark"] == "primitive" and "cpu_count" in report["machine"]
    r = report["results"]
    for key in ("primitive_decisions_per_s", "primitive_forward_ms_per_decision",
                "primitive_env_ms_per_decision", "primitive_policy_periods_per_s",
                "td3_updates_per_s", "td3_update_ms", "dense_policy_steps_per_s",
                "dense_forward_ms_per_step"):
        assert r[key] > 0, key
    assert r["policy_periods_per_decision"] >= 1  # a primitive is a whole approach and push
    assert r["decisions_to_dense_steps"] == pytest.approx(
        r["primitive_decisions_per_s"] / r["dense_policy_steps_per_s"])
    assert r["periods_to_dense_steps"] == pytest.approx(
        r["primitive_policy_periods_per_s"] / r["dense_policy_steps_per_s"])
    assert r["forward_primitive_to_dense"] == pytest.approx(
        r["primitive_forward_ms_per_decision"] / r["dense_forward_ms_per_step"])
    assert (r["decisions"], r["updates"], r["batch_size"], r["replay_transitions"]) == (2, 2, 4, 2)
    assert r["encoder"] == "random" and r["task"] == "push"


# --- a curriculum: --init-from -----------------------------------------------------------------
def test_init_from_starts_with_the_source_runs_actor_and_critic(tmp_path, capsys):
    import torch

    source, run = tmp_path / "source", tmp_path / "run"
    assert _train(source, 16) == 0
    trainer = PrimitiveTrainer.__new__(PrimitiveTrainer)  # only to read what a new run loads
    from corn_drake.config.plumbing.loader import load_config
    from corn_drake.config.primitive import PrimitiveTrainConfig
    from corn_drake.rl.pretrained_encoders import load_encoder

    cfg = load_config(PrimitiveTrainConfig, source / "config.yaml")
    cfg.init_from = str(source)
    trainer.__init__(cfg, tmp_path / "unused", load_encoder("corn", ENCODER))
    saved = _checkpoint(source)["agent"]
    for name, value in trainer.agent.actor.state_dict().items():
        assert torch.equal(value, saved["actor"][name]), name
    for name, value in trainer.learner.critic_target.state_dict().items():
        assert torch.equal(value, saved["critic"][name]), name
    assert trainer.global_step == 0 and len(trainer.replay) == 0
    # Through the command line, and a folder that is not a primitive run is refused.
    assert _train(run, 8, "--init-from", str(source)) == 0
    capsys.readouterr()
    assert _train(tmp_path / "bad", 8, "--init-from", str(tmp_path / "nothing")) == 2
    one_error_line(capsys, "nothing")
