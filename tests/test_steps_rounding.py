"""A PPO run trains whole rollouts: a --steps that is no multiple of one is said, with the count
trained (issue 63: `--steps 8` trained 128 without a word)."""

from corn_drake.cli import main


def test_the_steps_a_ppo_run_rounds_to_are_said(tmp_path, capsys):
    """`--steps 8` trained 128 without a word (whole rollouts of 4 envs x 32 steps): the line
    says the count trained, and the run's step count is that count."""
    import json

    from corn_drake.rl.training.ppo_trainer import steps_trained

    assert steps_trained(8, 0, 128) == 128 and steps_trained(256, 0, 128) == 256
    assert steps_trained(300, 256, 128) == 384 and steps_trained(100, 128, 128) == 128
    out = tmp_path / "run"
    assert main(["train", "--policy", "state", "--steps", "8", "--envs-per-worker", "2",
                 "--rollout-steps", "4", "--set", "task.episode_steps=5", "--no-progress",
                 "--out", str(out)]) == 0
    assert "--steps 8 is trained as 8" not in capsys.readouterr().out
    assert main(["train", "--policy", "state", "--steps", "12", "--out", str(out),
                 "--no-progress"]) == 0
    assert "--steps 12 is trained as 16: whole rollouts of 2 envs x 4 steps" in \
        capsys.readouterr().out
    assert json.loads((out / "metrics.json").read_text())["global_step"] == 16
