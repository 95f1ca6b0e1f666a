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

from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.config.training import TrainConfig
from corn_drake.rl.training.ppo_trainer import Trainer
from corn_drake.rl.envs.vec_env import EnvFactory
from tests.waiting import wait_until


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

    from corn_drake.commands.reporting import curves

    png = tmp_path / "both.png"
    assert curves.run(Namespace(runs=[str(tmp_path), str(tmp_path)], out=str(png), x="steps",
                                rate="median", rates="", summary="", history="")) == 0
    assert png.stat().st_size > 1000
    with pytest.raises(FileNotFoundError, match="no checkpoints"):
        curves.run(Namespace(runs=[str(tmp_path / "tb")], out=str(png), x="steps", rate="median", rates="",
                             summary="", history=""))


def test_snapshots_keep_the_checkpoint_of_each_multiple_and_load_by_name(tmp_path):
    from corn_drake.errors import MissingInputError
    from corn_drake.rl.checkpoints import run_snapshots, snapshot_path
    from corn_drake.rl.ppo.teacher_runs import load_run_with_step
    from corn_drake.run_folders.config_file import write_run_config

    cfg = _small_cfg(160)  # 5 updates of 32 steps
    cfg.snapshot_every = 64  # passed at 64 and 128 (96 and 160 pass no new multiple)
    write_run_config(cfg, tmp_path)
    trainer = Trainer(cfg, tmp_path)
    trainer.train(progress=False)
    assert run_snapshots(tmp_path) == ["step_000000064.pt", "step_000000128.pt"]
    _, agent, step = load_run_with_step(tmp_path, "step_000000064.pt")
    assert step == 64
    _, last, last_step = load_run_with_step(tmp_path)
    assert last_step == 160
    # The snapshot holds the weights of its own step, not the last ones.
    assert any(not torch.equal(a, b) for a, b in zip(agent.state_dict().values(),
                                                     last.state_dict().values()))
    for bad in ("step_000000096.pt", "../checkpoints/last.pt"):
        with pytest.raises(MissingInputError, match="step_000000064.pt, step_000000128.pt"):
            load_run_with_step(tmp_path, bad)
    # A resumed run that passes a kept step again rewrites its snapshot; prev.pt (the checkpoint
    # before last.pt) stays, instead of taking the old snapshot's place.
    prev = (tmp_path / "checkpoints" / "prev.pt").read_bytes()
    trainer._save(snapshot_path(tmp_path, 64))
    assert (tmp_path / "checkpoints" / "prev.pt").read_bytes() == prev
    assert load_run_with_step(tmp_path, "step_000000064.pt")[2] == 160


@pytest.mark.slow
def test_killed_training_process_resumes_from_its_checkpoint(tmp_path):
    cmd = [sys.executable, "-m", "corn_drake.cli", "train", "--policy", "state", "--steps", "100000",
           "--envs-per-worker", "2", "--rollout-steps", "16", "--set", "task.episode_steps=20",
           "--out", str(tmp_path), "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ckpt = tmp_path / "checkpoints" / "last.pt"
    # checkpoint_every defaults to 5 updates: wait for the first (no deadline: the cap only
    # guards against a hang), then a bit more.
    wait_until(lambda: ckpt.exists() or proc.poll() is not None, "the first checkpoint",
               poll_s=0.5)
    assert ckpt.exists(), f"the run ended ({proc.returncode}) without a checkpoint"
    time.sleep(1.0)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    state = torch.load(ckpt, weights_only=False)  # the atomic write left a complete file
    assert state["global_step"] > 0
    resumed = Trainer(_small_cfg(state["global_step"] + 32), tmp_path)
    assert resumed.global_step == state["global_step"]
    resumed.train(progress=False)
    assert resumed.global_step == state["global_step"] + 32
    # A kill during a save leaves its temporary file (no cleanup runs on SIGKILL); the resumed
    # run's first save removes it.
    assert not list(ckpt.parent.glob(".*tmp"))


def test_ray_workers_survive_a_killed_worker():
    ray = pytest.importorskip("ray")
    from corn_drake.rl.workers.ray_workers import RayEnvBatch, init_ray

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


def test_frozen_encoder_runs_once_per_observation_batch_and_never_in_the_update(tmp_path):
    from corn_drake.rl.pretrained_encoders import make_encoder
    from corn_drake.rl.ppo.ppo import compute_gae

    cfg = TrainConfig(policy="corn", total_steps=8, envs_per_worker=2, rollout_steps=4)
    cfg.env.task.episode_steps = 3  # episodes end inside the rollout: final values are needed
    encoder, calls = make_encoder("corn"), []
    encoder.register_forward_pre_hook(lambda module, args: calls.append(1))  # counts, changes nothing
    trainer = Trainer(cfg, tmp_path, encoder)
    rollout = trainer._collect()
    stack, flat_obs = rollout.stack, rollout.obs
    ended = stack["terminated"].bool() | stack["truncated"].bool()
    assert ended.any(dim=1).sum() >= 1
    # One call per rollout step, one per step where episodes ended (their final observations),
    # one for the value after the rollout.
    assert len(calls) == cfg.rollout_steps + int(ended.any(dim=1).sum()) + 1
    adv, ret = compute_gae(stack["rewards"], stack["values"], stack["terminated"],
                           stack["truncated"], stack["final_values"], rollout.last_values,
                           0.99, 0.95)
    calls.clear()
    stats = trainer.ppo.update(flat_obs, stack["actions"].flatten(0, 1), stack["logp"].flatten(0, 1),
                               adv.flatten(), ret.flatten())
    assert stats["minibatches"] >= 1 and not calls


def _library_config(library, episode_steps):
    cfg = TeacherDiagramConfig()
    obj = cfg.scene.object
    obj.kind, obj.library, obj.library_objects = "library", str(library), "train"
    cfg.task.episode_steps = episode_steps
    return cfg


def test_envs_move_through_every_train_object(tmp_path):
    from corn_drake.assets.library import list_objects
    from corn_drake.rl.envs.vec_env import EnvBatch
    from tests.fixtures import write_loadable_library

    library = write_loadable_library(tmp_path / "lib", num_train=10)
    train_ids = list_objects(library, "train")
    batch = EnvBatch(EnvFactory(_library_config(library, episode_steps=2), seed=0), num_envs=4)
    batch.reset()
    episodes, first_poses = [], []
    for _ in range(6):  # 3 episodes per env
        result = batch.step(np.zeros((4, 20)))
        episodes += result.episode_stats
        first_poses += [batch.envs[i].episode.initial_object_pose for i in result.final_obs]
    assert len(episodes) == 12 and {e["object"] for e in episodes} == set(train_ids)
    for _ in range(18):  # into the second round of objects
        batch.step(np.zeros((4, 20)))
    # Switching reuses the envs built for each object (pydrake never frees a discarded
    # diagram): about one per object, not one per episode (4 + 48 here).
    assert batch.built <= len(train_ids) + 4
    # No env repeats an object within a round of len(train_ids) episodes, and envs at the same
    # episode count hold different objects.
    per_env = [[batch.factory.object_for(i, k) for k in range(10)] for i in range(4)]
    assert all(sorted(objects) == sorted(train_ids) for objects in per_env)
    assert all(len({per_env[i][k] for i in range(4)}) == 4 for k in range(10))
    # The schedule and the episodes are seeded: a second batch replays them exactly.
    again = EnvBatch(EnvFactory(_library_config(library, episode_steps=2), seed=0), num_envs=4)
    again.reset()
    replay, replay_poses = [], []
    for _ in range(6):
        result = again.step(np.zeros((4, 20)))
        replay += result.episode_stats
        replay_poses += [again.envs[i].episode.initial_object_pose for i in result.final_obs]
    assert [e["object"] for e in replay] == [e["object"] for e in episodes]
    np.testing.assert_allclose(replay_poses, first_poses)


def test_a_fixed_object_id_keeps_one_object(tmp_path):
    from corn_drake.rl.envs.vec_env import EnvBatch
    from tests.fixtures import write_loadable_library

    library = write_loadable_library(tmp_path / "lib", num_train=3)
    cfg = _library_config(library, episode_steps=1)
    cfg.scene.object.library_objects, cfg.scene.object.object_id = "one", "cylinder_01"
    batch = EnvBatch(EnvFactory(cfg, seed=0), num_envs=2)
    batch.reset()
    envs = list(batch.envs)
    stats = [s for _ in range(3) for s in batch.step(np.zeros((2, 20))).episode_stats]
    assert {s["object"] for s in stats} == {"cylinder_01"} and len(stats) == 6
    assert all(a is b for a, b in zip(envs, batch.envs))  # never rebuilt
    with pytest.raises(ValueError, match="actions: expected one row per env"):
        batch.step(np.zeros((3, 20)))


@pytest.mark.slow
def test_train_cli_writes_episodes_per_object_for_every_train_object(tmp_path):
    """A tiny `train` over a 6-object library (plus one unseen) trains on all six, and a resume
    keeps counting from the checkpoint."""
    from corn_drake.assets.library import list_objects
    from tests.fixtures import write_loadable_library

    library = write_loadable_library(tmp_path / "lib", num_train=6)
    out = tmp_path / "run"

    def train(steps):
        cmd = [sys.executable, "-m", "corn_drake.cli", "train", "--policy", "state",
               "--objects", str(library), "--steps", str(steps), "--envs-per-worker", "2",
               "--rollout-steps", "8", "--set", "task.episode_steps=3", "--out", str(out),
               "--no-progress"]
        subprocess.run(cmd, check=True, capture_output=True)
        return json.loads((out / "metrics.json").read_text())

    first = train(32)["episodes_per_object"]
    assert set(first) == set(list_objects(library, "train"))  # every train object, no unseen one
    resumed = train(64)
    counts = resumed["episodes_per_object"]
    assert all(counts[o] >= n for o, n in first.items())
    assert sum(counts.values()) == sum(first.values()) + sum(
        h["episodes"] for h in resumed["history"][len(resumed["history"]) // 2:])


def test_a_failed_simulation_step_ends_the_episode_without_bootstrap(tmp_path):
    from corn_drake.rl.ppo.ppo import compute_gae

    trainer = Trainer(_small_cfg(64), tmp_path)
    trainer.rollouts.reset()
    env = trainer.envs.envs[0]
    # A huge object velocity makes the next step fail (the solver or a non-finite state).
    n_v = env.scene.plant.num_velocities(env.scene.object_instance)
    env.scene.plant.SetVelocities(env.plant_context, env.scene.object_instance, np.full(n_v, 1e300))
    rollout = trainer._collect()
    episodes, stack = rollout.episodes, rollout.stack
    assert rollout.sim_errors == 1
    assert [e["sim_error"] for e in episodes] == [True] and episodes[0]["length"] == 1
    assert stack["terminated"][0].tolist() == [1.0, 0.0]
    assert stack["truncated"][0].tolist() == [0.0, 0.0]
    adv, _ = compute_gae(stack["rewards"], stack["values"], stack["terminated"], stack["truncated"],
                         stack["final_values"], rollout.last_values, 0.99, 0.95)
    # Ended, not cut: the advantage is the reward minus the value, nothing bootstrapped after.
    torch.testing.assert_close(adv[0, 0], stack["rewards"][0, 0] - stack["values"][0, 0])


def test_ray_workers_share_the_object_rounds_of_an_in_process_batch(tmp_path):
    """Workers' envs take their global index and the total env count: 2 workers x 2 envs run
    the same objects and episodes as one in-process batch of 4."""
    ray = pytest.importorskip("ray")
    from corn_drake.rl.workers.ray_workers import RayEnvBatch, init_ray
    from corn_drake.rl.envs.vec_env import EnvBatch
    from tests.fixtures import write_loadable_library

    factory = EnvFactory(_library_config(write_loadable_library(tmp_path / "lib", 4), 1), seed=3)

    def run(batch):
        first = batch.reset()
        stats = [s for _ in range(3) for s in batch.step(np.zeros((4, 20))).episode_stats]
        return first["goal"], [(s["object"], s["return"]) for s in stats]

    goal, local = run(EnvBatch(factory, 4))
    assert {o for o, _ in local} == set(factory.train_objects)
    init_ray(num_cpus=2)
    try:
        remote_goal, remote = run(RayEnvBatch(factory, num_workers=2, envs_per_worker=2))
    finally:
        ray.shutdown()
    np.testing.assert_allclose(remote_goal, goal)
    assert [o for o, _ in remote] == [o for o, _ in local]
    np.testing.assert_allclose([r for _, r in remote], [r for _, r in local], rtol=1e-9)


def test_a_run_started_from_another_carries_its_agent_and_refuses_another_network(tmp_path, capsys):
    from corn_drake.cli import main
    from corn_drake.rl.ppo.teacher_runs import load_run

    source = tmp_path / "push"
    assert main(["train", "--policy", "state", "--task", "push", "--steps", "32",
                 "--envs-per-worker", "2", "--rollout-steps", "16", "--out", str(source),
                 "--no-progress"]) == 0
    _, trained = load_run(source)
    # No --policy: the source's is taken; the new run starts from its trained agent.
    turn = tmp_path / "turn"
    assert main(["train", "--init-from", str(source), "--task", "push_turn", "--steps", "32",
                 "--envs-per-worker", "2", "--rollout-steps", "16", "--set",
                 "ppo.lr=1e-12", "--set", "ppo.lr_min=1e-12", "--set", "ppo.critic_lr=1e-12", "--out", str(turn),
                 "--no-progress"]) == 0
    cfg, carried = load_run(turn)
    assert cfg.init_from == str(source) and cfg.env.task.name == "push_turn"
    for (name, a), b in zip(trained.state_dict().items(), carried.state_dict().values()):
        # The observation normalisers moved with the new run's batch; the weights barely did.
        if "normalizer" not in name:
            torch.testing.assert_close(a, b, atol=1e-6, rtol=0, msg=name)
    for extra, named in ((["--set", "ppo.separate_critic=false"], "its ppo.separate_critic"),
                         (["--policy", "e2e"], "its policy is 'state'")):
        assert main(["train", "--init-from", str(source), *extra, "--out",
                     str(tmp_path / "other"), "--no-progress"]) != 0
        assert named in capsys.readouterr().err
    assert not (tmp_path / "other" / "config.yaml").exists()
