"""Rollout workers as Ray actors: each holds an EnvBatch; the learner batches inference.

RayEnvBatch looks like EnvBatch (reset / step over all envs of all workers, concatenated). A worker
that dies (process killed, node lost) is replaced by a fresh actor with the same envs; its envs
start new episodes, the step reports them as truncated with no bootstrap (final_obs absent), and
`restarts` counts it, one line saying which worker, where and why (rl/workers/cluster.py) — the
run goes on.
"""

from __future__ import annotations

import contextlib
import dataclasses

import numpy as np
import ray

from corn_drake.rl.envs.vec_env import EnvBatch, EnvFactory, StepResult, concat_obs
from corn_drake.rl.workers import cluster
from corn_drake.rl.workers.cluster import WorkerBase, arrive, spawn_replacement, worker_options


@ray.remote(num_cpus=1)
class RolloutWorker(WorkerBase):
    def __init__(self, factory: EnvFactory, num_envs: int, first_index: int, library=None):
        import torch

        torch.set_num_threads(1)  # its inference must not spread threads over the other workers
        factory = arrive(factory, library)  # the library as this node holds it
        self.batch = EnvBatch(factory, num_envs, first_index)

    def reset(self):
        return self.batch.reset()

    def step(self, actions: np.ndarray) -> StepResult:
        return self.batch.step(actions)


def init_ray(address: str | None = None, num_cpus: int | None = None) -> None:
    """A Ray of this process's own by default (`num_cpus`, else the CPUs this process may use),
    never a cluster it did not name; the cluster at `address` with it. No dashboard (nothing to
    serve here).

    A local Ray's processes end with this process, however it ends: see ray_reaper.py. (Ray
    2.x starts its DashboardAgent and RuntimeEnvAgent even without the dashboard; there is no
    switch to keep them away, so the reaper ends them.)
    """
    from corn_drake.nn.threads import usable_cpus

    if ray.is_initialized():
        return
    with _signals_held_during_start():
        if address:
            # One line now, not minutes of ray.init retrying an address nothing answers at.
            # Every trainer starts Ray before its command writes the run folder: nothing is
            # recorded for a refused address.
            cluster.check_ray_address(address, "--ray-address")
            ray.init(address=address, log_to_driver=False)
            cluster.joined_cluster = True
            return
        before = _child_pids()
        with _ray_processes_in_their_own_session():
            # address="local": a Ray of our own, whatever cluster this machine started or left
            # behind. Without it ray.init joins the cluster named by RAY_ADDRESS or by Ray's
            # current-cluster file (left there after `ray start`, even once stopped): a local
            # run then ran on someone's cluster, or failed on num_cpus (issue 56).
            ray.init(address="local", num_cpus=num_cpus or usable_cpus(),
                     include_dashboard=False, log_to_driver=False)
        cluster.joined_cluster = False
        _start_reaper(sorted(_child_pids() - before))


@contextlib.contextmanager
def _ray_processes_in_their_own_session():
    """Ray's processes (GCS, raylet and the workers the raylet starts) in a session of their
    own, out of the command's process group.

    A supervisor that signals the whole group (GNU timeout, SLURM, `kill -- -PGID`) would
    otherwise reach the raylet and object store too; the command's core worker then loses its
    objects and exits 1 before the command's own SIGTERM handler can say one line and end with
    143. Out of the group, only the command hears the signal and shuts its Ray down in order;
    if it dies instead, the reaper (ray_reaper.py) and Ray's own parent-death signal end them."""
    import ray._private.services as services

    popen = services.ConsolePopen

    class OwnSession(popen):
        def __init__(self, *args, **kwargs):
            kwargs.setdefault("start_new_session", True)
            super().__init__(*args, **kwargs)

    services.ConsolePopen = OwnSession
    try:
        yield
    finally:
        services.ConsolePopen = popen


@contextlib.contextmanager
def _signals_held_during_start():
    """SIGINT / SIGTERM arriving while ray.init runs are held and delivered once it returns
    (corn_drake/signals.py). ray.init puts its own handlers in while it starts: a Python
    SIGTERM handler that calls sys.exit from inside its start-up (a native stack dump and exit
    134; kept from being set here) and native ones once its core worker connects; held, the
    signal reaches the command line's handlers (cli.py: one line, exit 130 / 143) instead."""
    import ray._private.utils as ray_utils

    from corn_drake.signals import held_signals

    set_sigterm_handler = ray_utils.set_sigterm_handler
    ray_utils.set_sigterm_handler = lambda handler: None
    try:
        with held_signals():
            yield
    finally:
        ray_utils.set_sigterm_handler = set_sigterm_handler


# The running reaper; holding it keeps our end of its stdin pipe open until this process dies.
_reaper = None


def _child_pids() -> set[int]:
    import psutil

    return {p.pid for p in psutil.Process().children()}


def _start_reaper(pids: list[int]) -> None:
    import subprocess
    import sys
    from pathlib import Path

    global _reaper
    if not pids:
        return
    script = Path(__file__).with_name("ray_reaper.py")
    # Its own session: a Ctrl-C or hang-up sent to our process group must not reach it.
    _reaper = subprocess.Popen([sys.executable, str(script), *map(str, pids)],
                               stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL, start_new_session=True)


class RayEnvBatch:
    def __init__(self, factory: EnvFactory, num_workers: int, envs_per_worker: int):
        if not factory.num_envs:  # every worker's envs share the object rounds
            factory = dataclasses.replace(factory, num_envs=num_workers * envs_per_worker)
        self.factory, self.envs_per_worker = factory, envs_per_worker
        cluster.start_pool(self, factory, num_workers, "rollout")

    def _spawn(self, w: int):
        return RolloutWorker.options(**worker_options(self.cpus)).remote(
            self.factory, self.envs_per_worker, w * self.envs_per_worker, self._library)

    def __len__(self) -> int:
        return len(self.workers) * self.envs_per_worker

    def reset(self) -> dict[str, np.ndarray]:
        parts = ray.get([w.reset.remote() for w in self.workers])
        return concat_obs(parts)

    def step(self, actions: np.ndarray) -> StepResult:
        E = self.envs_per_worker
        futures = [w.step.remote(actions[i * E:(i + 1) * E]) for i, w in enumerate(self.workers)]
        results = []
        for i, future in enumerate(futures):
            try:
                results.append(ray.get(future))
            except (ray.exceptions.RayActorError, ray.exceptions.WorkerCrashedError) as e:
                results.append(self._replace(i, e))
        return _concat(results, E)

    def _replace(self, i: int, error: Exception) -> StepResult:
        self.restarts += 1
        spawn_replacement(self.record.kind, self.workers, i, self.cpus, lambda: self._spawn(i))
        self.record.replaced(i, error, self.workers[i], "its envs starting new episodes")
        obs = ray.get(self.workers[i].reset.remote())
        E = self.envs_per_worker
        return StepResult(obs, np.zeros(E), np.zeros(E, bool), np.ones(E, bool), {}, [],
                          sim_errors=0)

    def worker_pids(self) -> list[int]:
        return ray.get([w.pid.remote() for w in self.workers])


def _concat(results: list[StepResult], per_worker: int) -> StepResult:
    final_obs = {i * per_worker + j: o for i, r in enumerate(results) for j, o in r.final_obs.items()}
    return StepResult(
        obs=concat_obs([r.obs for r in results]),
        rewards=np.concatenate([r.rewards for r in results]),
        terminated=np.concatenate([r.terminated for r in results]),
        truncated=np.concatenate([r.truncated for r in results]),
        final_obs=final_obs,
        episode_stats=[s for r in results for s in r.episode_stats],
        sim_errors=sum(r.sim_errors for r in results))
