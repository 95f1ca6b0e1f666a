"""Ray workers that step their own envs for whole rollout segments (rl/workers/segment_workers.py): the
same episodes as in-process collection, the weights of the update they collect for, and a worker
killed mid-rollout replaced without losing the update."""

import os
import signal
import threading

import numpy as np
import pytest
import torch

from corn_drake.config.training import TrainConfig
from corn_drake.nn.threads import torch_threads
from corn_drake.rl.envs.vec_env import EnvBatch
from corn_drake.rl.ppo.segments import SegmentCollector, concat_segments
from corn_drake.rl.training.ppo_trainer import Trainer
from corn_drake.rl.run_progress import run_env_factory
from tests.waiting import wait_until

ray = pytest.importorskip("ray")

ENVS = 4
WORKERS = 2


def _cfg(workers: int, total_updates: int = 1, rollout: int = 8) -> TrainConfig:
    cfg = TrainConfig(policy="state", workers=workers, envs_per_worker=ENVS // max(workers, 1),
                      rollout_steps=rollout, total_steps=total_updates * ENVS * rollout,
                      checkpoint_every=1)
    cfg.env.task.episode_steps = 5  # episodes end inside a segment: resets and final values
    return cfg


@pytest.fixture(scope="module")
def local_ray():
    from corn_drake.rl.workers.ray_workers import init_ray

    # CPUs to spare: a test's trainers hold their workers (1 CPU each) side by side.
    init_ray(num_cpus=8)
    yield
    ray.shutdown()


class _WorkersInProcess(Trainer):
    """In-process collection computed exactly as the Ray workers compute it: one
    SegmentCollector per worker over that worker's envs (the same factory and env indices),
    stepped by the learner's own agent at one torch thread (what every worker runs at:
    segment_workers.SegmentWorker), and the parts joined in worker order like
    RaySegmentCollectors.collect. It differs from the Ray path only in what the test is about:
    no Ray, no weights broadcast, no segments shipped back.

    Why not the plain workers=0 path (one batch of 4 envs): batched inference over 2 envs and
    over 4 may round differently in the last bits (another matmul blocking; on some CPUs,
    another SIMD kernel), and contact physics amplifies that over a segment past any
    tolerance one could justify (issue 53: robot_state differed on another machine). Inference
    over the same batches at the same thread count on one machine is bit for bit the same, so
    against this reference the Ray path must agree exactly, on any machine."""

    def _make_rollouts(self, n_envs: int):
        cfg, E = self.cfg, self.cfg.envs_per_worker
        start = sum(self.episodes_per_object.values()) // n_envs  # as Trainer._make_rollouts
        factory = run_env_factory(cfg.env, cfg.seed, cfg.workers, E, start)
        return _JoinedCollectors([SegmentCollector(EnvBatch(factory, E, w * E), self.agent,
                                                   self.device) for w in range(cfg.workers)])


class _JoinedCollectors:
    def __init__(self, parts: list[SegmentCollector]):
        self.parts = parts

    def __len__(self) -> int:
        return sum(len(p) for p in self.parts)

    def sync(self, agent, version: int) -> None:
        for part in self.parts:
            part.sync(agent, version)

    def collect(self, noise):
        E = len(self.parts[0])
        with torch_threads(1):
            return concat_segments([p.collect(noise[:, i * E:(i + 1) * E])
                                    for i, p in enumerate(self.parts)])


def _assert_same_rollout(a, b) -> None:
    """Bit for bit: callers compare collections that run the same inference batches at the same
    thread count on this machine (see _WorkersInProcess), so nothing may differ at all."""
    def same(x, y, msg):
        torch.testing.assert_close(x, y, rtol=0, atol=0, msg=msg)

    for key in a.stack:
        same(a.stack[key], b.stack[key], key)
    for key in a.obs:
        same(a.obs[key], b.obs[key], key)
    same(a.last_values, b.last_values, "last_values")
    assert a.episodes == b.episodes


def test_ray_workers_collect_the_same_segments_and_updates_as_in_process(tmp_path, local_ray):
    # The in-process reference batches inference per worker (_WorkersInProcess), so both sides
    # compute the same numbers and must agree bit for bit on any machine: a worker's envs,
    # its columns of the noise, the join order and the weights it acts with all show exactly.
    local = _WorkersInProcess(_cfg(WORKERS, total_updates=2), tmp_path / "local")
    remote = Trainer(_cfg(WORKERS, total_updates=2), tmp_path / "remote")
    first = local._collect()
    assert first.episodes  # 8 steps of 5-step episodes: every env ended one
    _assert_same_rollout(remote._collect(), first)
    # Whole updates: the second segment acts with the weights after the first update, which
    # the workers only have through the broadcast (stale weights would change its actions).
    # Both learners update in this process from the same rollouts, so the weights agree
    # exactly too.
    local = _WorkersInProcess(_cfg(WORKERS, total_updates=2), tmp_path / "local2")
    remote = Trainer(_cfg(WORKERS, total_updates=2), tmp_path / "remote2")
    a, b = local.train(progress=False), remote.train(progress=False)
    assert [h["return"] for h in a["history"]] == [h["return"] for h in b["history"]]
    for (name, p), q in zip(local.agent.state_dict().items(), remote.agent.state_dict().values()):
        torch.testing.assert_close(p, q, rtol=0, atol=0, msg=name)
    assert b["final"]["worker_restarts"] == 0


def test_a_worker_acts_with_the_weights_of_the_update_it_collects_for(tmp_path, local_ray):
    trainer = Trainer(_cfg(2), tmp_path)
    old = {k: v.clone() for k, v in trainer.agent.state_dict().items()}
    with torch.no_grad():  # what an update does to the weights, as far as the workers can tell
        for p in trainer.agent.parameters():
            p.add_(0.05 * torch.randn_like(p))
    trainer.update_index = 1
    rollout = trainer._collect()
    T = trainer.cfg.rollout_steps
    with torch.no_grad():
        values = trainer.agent(rollout.obs)[1].reshape(T, ENVS)
        trainer.agent.load_state_dict(old)
        old_values = trainer.agent(rollout.obs)[1].reshape(T, ENVS)
    torch.testing.assert_close(rollout.stack["values"], values, atol=1e-5, rtol=1e-5)
    assert not torch.allclose(rollout.stack["values"], old_values, atol=1e-3)
    # Weights not sent for this update: the segment says so and the learner refuses it.
    trainer.update_index = 2
    trainer.rollouts.sync = lambda agent, version: None
    with pytest.raises(RuntimeError, match="update 1's weights in update 2"):
        trainer._collect()


def test_a_worker_killed_mid_rollout_is_replaced_without_losing_the_update(tmp_path, local_ray):
    rollout_steps = 60  # a second or more of stepping: the kill lands inside it
    # The same worker layout (not in-process: over 60 steps the last-bit differences of
    # another inference batch size grow through the contacts).
    undisturbed = Trainer(_cfg(2, rollout=rollout_steps), tmp_path / "undisturbed")._collect()
    trainer = Trainer(_cfg(2, rollout=rollout_steps), tmp_path / "remote")
    victim = trainer.rollouts.worker_pids()[0]
    done = []
    collecting = threading.Thread(target=lambda: done.append(trainer._collect()))
    collecting.start()
    # Kill once the worker is busy with the segment (its CPU time moves): early in its ~1 s of
    # stepping, so the kill lands inside it even on a busy machine (a kill before it starts
    # would be replaced the same way; one after it ends would test nothing, and fail).
    import psutil

    process = psutil.Process(victim)
    busy_from = sum(process.cpu_times()[:2])
    wait_until(lambda: sum(process.cpu_times()[:2]) > busy_from + 0.05,
               "the worker to start stepping", poll_s=0.05)
    os.kill(victim, signal.SIGKILL)
    collecting.join()
    assert trainer.rollouts.restarts == 1 and done
    # The replacement collected the dead worker's segment again from its envs' first episodes,
    # with the same weights and noise: the update is the one nothing disturbed.
    _assert_same_rollout(done[0], undisturbed)
    assert np.isfinite(done[0].stack["values"].numpy()).all()
