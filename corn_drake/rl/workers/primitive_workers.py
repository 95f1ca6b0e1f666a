"""Ray workers that collect contact primitives on their own envs, for the off-policy learner.

Each PrimitiveWorker holds an EnvBatch, a CPU copy of the PrimitiveAgent (the frozen encoder,
the actor and the critic) and a random stream of its own, and runs PrimitiveCollector rounds
(rl/primitive/collection.py): it chooses with its copy of the networks, steps its envs, runs the
encoder on what they observe, and returns the transitions. The learner never steps an env or
runs the encoder: it adds what arrives to its replay and takes its TD3 updates.

Collection is asynchronous, as off-policy learning allows: every worker always has a request in
flight; when one returns, the learner stores its transitions, takes their updates, and sends
that worker its next request with the weights as they are then (put into Ray's object store once
per weights version). So the workers step while the learner updates, and a worker acts with
weights at most one request old. The order in which workers return depends on timing, so a Ray
run is not repeatable step for step (the in-process path is).

A worker that dies is replaced by a fresh one with the same envs and a fresh random stream,
which collects the lost request again (its rounds, not its exact primitives: new episodes, new
draws); `restarts` counts it. More than MAX_REPLACEMENTS replacements in a row without a
request coming back means the fault is not the worker's, and the run fails. Each replacement
says in one line which worker, where and why; a lost node's workers come back on the nodes left,
or the run stops with one line when they have no room (rl/workers/cluster.py).
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import ray

from corn_drake.rl.primitive.hindsight import HindsightRule
from corn_drake.rl.primitive.collection import (
    Exploration,
    PrimitiveCollector,
    PrimitiveTransitions,
)
from corn_drake.rl.envs.vec_env import EnvBatch, EnvFactory
from corn_drake.rl.workers import cluster
from corn_drake.rl.workers.cluster import WorkerBase, arrive, spawn_replacement, worker_options

MAX_REPLACEMENTS = 3


@ray.remote(num_cpus=1)
class PrimitiveWorker(WorkerBase):
    def __init__(self, factory: EnvFactory, num_envs: int, first_index: int, agent,
                 seed: list[int], hindsight: HindsightRule | None = None, library=None):
        import torch

        torch.set_num_threads(1)  # its inference must not spread threads over the other workers
        factory = arrive(factory, library)  # the library as this node holds it
        self.collector = PrimitiveCollector(EnvBatch(factory, num_envs, first_index), agent,
                                            hindsight=hindsight)
        self.rng = np.random.default_rng(seed)

    def collect(self, state: dict, version: int, rounds: int,
                exploration: Exploration) -> PrimitiveTransitions:
        self.collector.set_weights(state, version)
        return self.collector.collect(rounds, exploration, self.rng)


class RayPrimitiveCollectors:
    """`num_workers` PrimitiveWorkers of `envs_per_worker` envs each. `seed` and `start_step`
    seed the workers' random streams (a resumed run's workers draw new ones); `hindsight`: the
    workers relabel their finished episodes (rl/primitive/hindsight.py)."""

    def __init__(self, factory: EnvFactory, num_workers: int, envs_per_worker: int, agent,
                 seed: int, start_step: int = 0, hindsight: HindsightRule | None = None):
        if not factory.num_envs:  # every worker's envs share the object rounds
            factory = dataclasses.replace(factory, num_envs=num_workers * envs_per_worker)
        self.factory, self.envs_per_worker, self.hindsight = factory, envs_per_worker, hindsight
        self._seed, self._start_step = int(seed), int(start_step)
        # The networks' architecture and the encoder travel once, at spawn.
        self._agent = ray.put(copy.deepcopy(agent).cpu())
        self._spawns = [0] * num_workers
        cluster.start_pool(self, factory, num_workers, "primitive")
        self.version, self._weights = None, None
        self._pending: dict = {}  # future -> (worker index, rounds, exploration): to resend
        self._replaced_in_a_row = 0

    def _spawn(self, w: int):
        seed = [self._seed, w, self._spawns[w], self._start_step]
        self._spawns[w] += 1
        return PrimitiveWorker.options(**worker_options(self.cpus)).remote(
            self.factory, self.envs_per_worker, w * self.envs_per_worker, self._agent, seed,
            self.hindsight, self._library)

    def publish(self, agent, version: int) -> None:
        """Puts `agent`'s actor and critic (after update `version`) into the object store, once
        per version; the requests sent after this act with them."""
        from corn_drake.rl.run_progress import to_cpu

        if version != self.version:
            self._weights = ray.put(to_cpu(agent.network_state()))
            self.version = version

    def submit(self, w: int, rounds: int, exploration: Exploration) -> None:
        future = self.workers[w].collect.remote(self._weights, self.version, rounds, exploration)
        self._pending[future] = (w, rounds, exploration)

    def idle_workers(self) -> list[int]:
        busy = {w for w, _, _ in self._pending.values()}
        return [w for w in range(len(self.workers)) if w not in busy]

    def next_ready(self) -> tuple[int, PrimitiveTransitions]:
        """(worker index, its transitions) of the first request to come back; a dead worker is
        replaced on the way, and its request sent again to the replacement."""
        while True:
            if not self._pending:
                raise RuntimeError("no collection request in flight")
            [future], _ = ray.wait(list(self._pending), num_returns=1)
            w, rounds, exploration = self._pending.pop(future)
            try:
                result = ray.get(future)
            except (ray.exceptions.RayActorError, ray.exceptions.WorkerCrashedError) as e:
                self._replaced_in_a_row += 1
                if self._replaced_in_a_row > MAX_REPLACEMENTS:
                    raise RuntimeError(f"primitive workers died {self._replaced_in_a_row} times "
                                       f"in a row without returning a round") from None
                self.restarts += 1
                spawn_replacement(self.record.kind, self.workers, w, self.cpus,
                                  lambda: self._spawn(w))
                self.record.replaced(w, e, self.workers[w], "sending its request again")
                self.submit(w, rounds, exploration)
                continue
            self._replaced_in_a_row = 0
            return w, result

    def worker_pids(self) -> list[int]:
        return ray.get([w.pid.remote() for w in self.workers])

    def close(self) -> None:
        for worker in self.workers:
            ray.kill(worker)
        self.workers, self._pending = [], {}
