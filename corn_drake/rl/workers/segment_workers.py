"""Ray workers that step their own envs for whole PPO rollout segments.

Each SegmentWorker holds an EnvBatch and a CPU copy of the learner's agent. Per update the
learner puts the agent's weights into Ray's object store once (every worker reads that one
copy), and sends each worker its columns of the update's unit noise; the worker runs batched
inference over its envs and steps them for the whole segment (rl/ppo/segments.py), and returns the
segment. So a worker pays one round trip per update instead of one per env step (the lock-step
RayEnvBatch, rl/workers/ray_workers.py, which the DAgger student still uses),
and the learner runs no per-step inference at all.

PPO stays on-policy: a segment carries the update whose weights it acted with, and the learner
refuses one from another update. A worker that dies (process killed, node lost) is replaced by
a fresh one with the same envs (new episodes from their first), which collects the dead
worker's segment again with the same weights and noise: the update loses nothing, `restarts`
counts it, and one line says which worker, where, and why (rl/workers/cluster.py). A node lost
mid-run is the same: its workers come back on the nodes left; when those have no room, the run
stops with one line (NoRoomForWorkers) and its last checkpoint as it was.
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import ray

from corn_drake.rl.ppo.segments import Segment, SegmentCollector, concat_segments
from corn_drake.rl.envs.vec_env import EnvBatch, EnvFactory
from corn_drake.rl.workers.cluster import WorkerBase, arrive, spawn_replacement, worker_options
from corn_drake.rl.workers import cluster

# A worker replaced this many times within one update's collection means the fault is not the
# worker's (a segment that always kills its process): the update fails instead of looping.
MAX_REPLACEMENTS_PER_UPDATE = 3


@ray.remote(num_cpus=1)
class SegmentWorker(WorkerBase):
    def __init__(self, factory: EnvFactory, num_envs: int, first_index: int, agent, library):
        import torch

        torch.set_num_threads(1)  # its inference must not spread threads over the other workers
        factory = arrive(factory, library)  # the library as this node holds it
        self.collector = SegmentCollector(EnvBatch(factory, num_envs, first_index), agent, "cpu")

    def collect(self, state: dict, version: int, noise: np.ndarray) -> Segment:
        self.collector.set_weights(state, version)
        return self.collector.collect(noise)

    def version(self) -> int:
        return self.collector.version


class RaySegmentCollectors:
    """`num_workers` SegmentWorkers of `envs_per_worker` envs each, looking like one
    SegmentCollector over all their envs (worker 0's first)."""

    def __init__(self, factory: EnvFactory, num_workers: int, envs_per_worker: int, agent):
        if not factory.num_envs:  # every worker's envs share the object rounds
            factory = dataclasses.replace(factory, num_envs=num_workers * envs_per_worker)
        self.factory, self.envs_per_worker = factory, envs_per_worker
        # The agent's architecture travels once, at spawn; weights come with every update.
        self._agent = ray.put(copy.deepcopy(agent).cpu())
        cluster.start_pool(self, factory, num_workers, "rollout")
        self.version = None  # the update whose weights are in the object store
        self._weights = None

    def _spawn(self, w: int):
        return SegmentWorker.options(**worker_options(self.cpus)).remote(
            self.factory, self.envs_per_worker, w * self.envs_per_worker, self._agent,
            self._library)

    def __len__(self) -> int:
        return len(self.workers) * self.envs_per_worker

    def sync(self, agent, version: int) -> None:
        """Puts `agent`'s weights (the state after update `version`) into the object store,
        once per version."""
        from corn_drake.rl.run_progress import to_cpu

        if version != self.version:
            self._weights = ray.put(to_cpu(agent.state_dict()))
            self.version = version

    def collect(self, noise: np.ndarray) -> Segment:
        E = self.envs_per_worker
        if noise.shape[1] != len(self):
            raise ValueError(f"noise: expected {len(self)} env columns, got {noise.shape[1]}")
        columns = [noise[:, i * E:(i + 1) * E] for i in range(len(self.workers))]
        futures = [w.collect.remote(self._weights, self.version, c)
                   for w, c in zip(self.workers, columns)]
        parts, replaced = [], 0
        for i, future in enumerate(futures):
            while True:
                try:
                    parts.append(ray.get(future))
                    break
                except (ray.exceptions.RayActorError, ray.exceptions.WorkerCrashedError) as e:
                    replaced += 1
                    if replaced > MAX_REPLACEMENTS_PER_UPDATE:
                        raise RuntimeError(f"rollout workers died {replaced} times collecting "
                                           f"update {self.version}'s segments") from None
                    self.restarts += 1
                    spawn_replacement(self.record.kind, self.workers, i, self.cpus,
                                      lambda: self._spawn(i))
                    self.record.replaced(i, e, self.workers[i],
                                         f"collecting update {self.version}'s segment again")
                    future = self.workers[i].collect.remote(self._weights, self.version,
                                                            columns[i])
        return concat_segments(parts)

    def worker_pids(self) -> list[int]:
        return ray.get([w.pid.remote() for w in self.workers])
