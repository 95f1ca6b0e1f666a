"""Ray workers that collect contact primitives on their own envs (rl/workers/primitive_workers.py): the
same transitions as the in-process collector for the same envs, weights and random stream, the
weights the learner last published, a killed worker replaced, and a whole `--workers` run that
trains, checkpoints and resumes."""

import os
import signal

import numpy as np
import pytest
import torch

from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
from corn_drake.config.primitive import PrimitiveTrainConfig
from corn_drake.nn.threads import torch_threads
from corn_drake.package_data import data_dir
from corn_drake.rl.pretrained_encoders import load_encoder
from corn_drake.rl.primitive.collection import Exploration, PrimitiveCollector
from corn_drake.rl.training.primitive_trainer import PrimitiveTrainer
from corn_drake.rl.envs.vec_env import EnvBatch
from tests.waiting import wait_until

ray = pytest.importorskip("ray")

ENCODER = data_dir("models") / "weights" / "push_corn" / "encoder.pt"
POLICY = Exploration(random=False, temperature=0.1, motion_noise=0.3)


def _cfg(workers: int, steps: int = 8) -> PrimitiveTrainConfig:
    # No hindsight goals: the replay then holds exactly the primitives collected.
    return PrimitiveTrainConfig(env=load_primitive_env_config("push"), workers=workers,
                                envs_per_worker=2, total_steps=steps, random_steps=0,
                                learning_starts=4, log_every=4, checkpoint_every=4,
                                hindsight_goals=0)


def _trainer(tmp_path, workers: int, steps: int = 8) -> PrimitiveTrainer:
    return PrimitiveTrainer(_cfg(workers, steps), tmp_path, load_encoder("corn", ENCODER))


@pytest.fixture(scope="module")
def local_ray():
    from corn_drake.rl.workers.ray_workers import init_ray

    # CPUs to spare: a test's trainers hold their workers (1 CPU each) side by side.
    init_ray(num_cpus=8)
    yield
    ray.shutdown()


def _perturb(agent) -> None:
    """What training does to the actor and critic, as far as a collector can tell."""
    with torch.no_grad():
        for p in list(agent.actor.parameters()) + list(agent.critic.parameters()):
            p.add_(0.05 * torch.randn_like(p))


def _assert_same(a, b) -> None:
    """Bit for bit: the caller runs the same envs' inference over the same batches at the
    worker's one torch thread, so nothing may differ (a tolerance would not hold on every
    machine anyway: after a push through contact, last-bit differences of the choices grow)."""
    np.testing.assert_array_equal(a.locations, b.locations)
    np.testing.assert_array_equal(a.motions, b.motions)
    np.testing.assert_array_equal(a.rewards, b.rewards)
    np.testing.assert_array_equal(a.terminated, b.terminated)
    for key in a.features:
        np.testing.assert_array_equal(a.features[key], b.features[key], err_msg=key)
        np.testing.assert_array_equal(a.next_features[key], b.next_features[key], err_msg=key)


def test_a_worker_collects_what_the_in_process_collector_does_with_the_published_weights(
        tmp_path, local_ray):
    trainer = _trainer(tmp_path, workers=1)
    workers = trainer.workers
    _perturb(trainer.agent)
    workers.publish(trainer.agent, version=7)
    workers.submit(0, 2, POLICY)
    w, remote = workers.next_ready()
    assert (w, remote.version, len(remote)) == (0, 7, 4)  # 2 rounds x 2 envs
    # The same envs (worker 0's: the first two of the run's object rounds), the learner's
    # current weights and the worker's random stream, in this process, at the worker's one
    # torch thread (primitive_workers.PrimitiveWorker): the same inference, not just close to it
    # (another thread count may split a kernel's work, and round, differently).
    local = PrimitiveCollector(EnvBatch(workers.factory, 2, 0), trainer.agent)
    rng = np.random.default_rng([trainer.cfg.seed, 0, 0, 0])
    with torch_threads(1):
        _assert_same(remote, local.collect(2, POLICY, rng))
    # The weights from before the perturbation choose other motions: the worker did use the
    # published ones.
    stale = PrimitiveCollector(EnvBatch(workers.factory, 2, 0),
                               _trainer(tmp_path / "fresh", workers=0).agent)
    first = stale.collect(1, POLICY, np.random.default_rng([trainer.cfg.seed, 0, 0, 0]))
    assert not np.allclose(first.motions, remote.motions[:2], atol=1e-3)
    workers.close()


def test_a_worker_killed_mid_round_is_replaced_and_its_round_collected_again(tmp_path,
                                                                           local_ray):
    trainer = _trainer(tmp_path, workers=1)
    workers = trainer.workers
    workers.publish(trainer.agent, version=0)
    victim = workers.worker_pids()[0]
    import psutil

    process = psutil.Process(victim)
    busy_from = sum(process.cpu_times()[:2])
    workers.submit(0, 20, POLICY)  # 20 rounds: seconds of stepping, the kill lands inside
    wait_until(lambda: sum(process.cpu_times()[:2]) > busy_from + 0.2,
               "the worker to start stepping", poll_s=0.05)
    os.kill(victim, signal.SIGKILL)
    w, transitions = workers.next_ready()
    assert workers.restarts == 1
    assert w == 0 and len(transitions) == 40 and transitions.version == 0
    assert workers.worker_pids()[0] != victim
    assert np.isfinite(transitions.rewards).all()
    workers.close()


def test_a_run_with_ray_workers_trains_checkpoints_and_resumes(tmp_path, local_ray):
    run = tmp_path / "run"
    trainer = _trainer(run, workers=2, steps=8)
    metrics = trainer.train(progress=False)
    assert metrics["global_step"] == 8 and metrics["final"]["worker_restarts"] == 0
    assert len(trainer.replay) == 8
    assert trainer.learner.updates > 0  # learning_starts 4: updates once the replay holds 4
    assert [row["step"] for row in metrics["history"]] == [4, 8]
    # Resumed with a larger budget: the step, replay and updates go on from the checkpoint.
    updates = trainer.learner.updates
    resumed = PrimitiveTrainer(_cfg(2, steps=16), run, load_encoder("corn", ENCODER))
    assert resumed.global_step == 8 and len(resumed.replay) == 8
    assert resumed.learner.updates == updates
    after = resumed.train(progress=False)
    assert after["global_step"] == 16 and len(resumed.replay) == 16
    assert resumed.learner.updates == updates + 8  # one update per primitive collected
