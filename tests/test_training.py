"""Teacher training: resume after a kill, checkpoints, logs; Ray workers survive a killed worker."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch

from corn_drake.config import TeacherDiagramConfig, TrainConfig
from corn_drake.rl.trainer import Trainer
from corn_drake.rl.vec_env import EnvFactory


def _small_cfg(total, init_log_std=0.0):
    cfg = TrainConfig(policy="state", total_steps=total, envs_per_worker=2, rollout_steps=16,
                      checkpoint_every=1, init_log_std=init_log_std)
    cfg.env.task.episode_steps = 20
    return cfg


def test_resume_continues_at_the_same_step_with_the_same_optimizer(tmp_path):
    first = Trainer(_small_cfg(64, init_log_std=-0.5), tmp_path)
    assert torch.equal(first.agent.log_std.detach(), torch.full((20,), -0.5))
    first.train(progress=False)
    saved_opt = first.ppo.optimizer.state_dict()
    # The checkpoint's trained log-std wins over the initial value (compared with the rest of
    # the agent below).
    resumed = Trainer(_small_cfg(128, init_log_std=-0.5), tmp_path)
    assert resumed.global_step == 64 and resumed.update_index == 2
    # The success/return window continues across the restart (episodes of 20 steps finished).
    assert first.recent_episodes and resumed.recent_episodes == first.recent_episodes
    for a, b in zip(saved_opt["state"].values(), resumed.ppo.optimizer.state_dict()["state"].values()):
        torch.testing.assert_close(a["exp_avg"], b["exp_avg"])
    for (name, p), q in zip(first.agent.state_dict().items(), resumed.agent.state_dict().values()):
        torch.testing.assert_close(p, q, msg=name)
    metrics = resumed.train(progress=False)
    assert metrics["global_step"] == 128 and len(resumed.history) == 4
    assert (tmp_path / "plots" / "learning_curve.png").stat().st_size > 1000
    assert any(p.name.startswith("events") for p in (tmp_path / "tb").iterdir())
    written = json.loads((tmp_path / "metrics.json").read_text())
    assert written["updates"] == 4 and [h["step"] for h in written["history"]] == [32, 64, 96, 128]
    ppo = resumed.cfg.ppo
    assert all(1 <= h["gradient_steps"] <= ppo.epochs * ppo.minibatches for h in written["history"])
    # `corn-drake curves` overlays runs from their checkpoints; a folder that is no run is named.
    from argparse import Namespace

    from corn_drake.commands import curves

    png = tmp_path / "both.png"
    assert curves.run(Namespace(runs=[str(tmp_path), str(tmp_path)], out=str(png))) == 0
    assert png.stat().st_size > 1000
    with pytest.raises(FileNotFoundError, match="no checkpoints"):
        curves.run(Namespace(runs=[str(tmp_path / "tb")], out=str(png)))


def test_killed_training_process_resumes_from_its_checkpoint(tmp_path):
    cmd = [sys.executable, "-m", "corn_drake.cli", "train", "--policy", "state", "--steps", "100000",
           "--envs-per-worker", "2", "--rollout-steps", "16", "--episode-steps", "20",
           "--out", str(tmp_path), "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ckpt = tmp_path / "checkpoints" / "last.pt"
    deadline = time.time() + 120
    # checkpoint_every defaults to 5 updates: wait for the first, then a bit more.
    while not ckpt.exists() and time.time() < deadline:
        time.sleep(0.5)
    assert ckpt.exists(), "no checkpoint written before the deadline"
    time.sleep(1.0)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    state = torch.load(ckpt, weights_only=False)  # the atomic write left a complete file
    assert state["global_step"] > 0 and not list(ckpt.parent.glob(".*tmp"))
    resumed = Trainer(_small_cfg(state["global_step"] + 32), tmp_path)
    assert resumed.global_step == state["global_step"]
    resumed.train(progress=False)
    assert resumed.global_step == state["global_step"] + 32


def test_ray_workers_survive_a_killed_worker():
    ray = pytest.importorskip("ray")
    from corn_drake.rl.ray_workers import RayEnvBatch, init_ray

    cfg = TeacherDiagramConfig()
    init_ray(num_cpus=2)
    try:
        batch = RayEnvBatch(EnvFactory(cfg, seed=0), num_workers=2, envs_per_worker=2)
        obs = batch.reset()
        assert obs["cloud"].shape == (4, 512, 3)
        batch.step(np.zeros((4, 20)))
        os.kill(batch.worker_pids()[0], signal.SIGKILL)
        result = batch.step(np.zeros((4, 20)))
        assert batch.restarts == 1
        assert result.truncated.tolist() == [True, True, False, False]  # its envs start afresh
        assert np.isfinite(result.obs["cloud"]).all()
        result = batch.step(np.zeros((4, 20)))
        assert not result.truncated.any()
    finally:
        ray.shutdown()


class _CountingEncoder(torch.nn.Module):
    """Isolates the frozen encoder: counts its forward calls, delegates the computation."""

    def __init__(self, encoder):
        super().__init__()
        self.encoder, self.calls = encoder, 0

    def forward(self, cloud, hand):
        self.calls += 1
        return self.encoder(cloud, hand)


def test_frozen_encoder_runs_once_per_observation_batch_and_never_in_the_update(tmp_path):
    from corn_drake.rl.encoders import make_encoder
    from corn_drake.rl.ppo import compute_gae

    cfg = TrainConfig(policy="corn", total_steps=8, envs_per_worker=2, rollout_steps=4)
    cfg.env.task.episode_steps = 3  # episodes end inside the rollout: final values are needed
    counter = _CountingEncoder(make_encoder("corn"))
    trainer = Trainer(cfg, tmp_path, counter)
    buf, last_values, _, _, _ = trainer._collect(trainer.envs.reset())
    ended = torch.stack([a.bool() | b.bool() for a, b in zip(buf["terminated"], buf["truncated"])])
    assert ended.any(dim=1).sum() >= 1
    # One call per rollout step, one per step where episodes ended (their final observations),
    # one for the value after the rollout.
    assert counter.calls == cfg.rollout_steps + int(ended.any(dim=1).sum()) + 1
    stack = {k: torch.stack(v) for k, v in buf.items() if k != "obs"}
    adv, ret = compute_gae(stack["rewards"], stack["values"], stack["terminated"],
                           stack["truncated"], stack["final_values"], last_values, 0.99, 0.95)
    flat_obs = {k: torch.cat([o[k] for o in buf["obs"]]) for k in buf["obs"][0]}
    counter.calls = 0
    stats = trainer.ppo.update(flat_obs, stack["actions"].flatten(0, 1), stack["logp"].flatten(0, 1),
                               adv.flatten(), ret.flatten())
    assert stats["minibatches"] >= 1 and counter.calls == 0
