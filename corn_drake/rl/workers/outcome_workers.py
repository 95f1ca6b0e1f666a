"""Outcome data over Ray workers (`collect-outcomes --workers N`, local cores or a cluster with
--ray-address): each worker collects whole chunks (outcome/collect.collect_chunk) and hands back
their arrays; the driver writes each chunk file as it comes, so the folder resumes exactly as
one process's would (a chunk already written is skipped). Episode k's data depends on k only,
so which worker plays it changes nothing. The objects reach a cluster's nodes through the
object store (cluster.pack_objects: no node reads the driver's disk). A worker that dies is
replaced and its chunk given to another, collected again from its episodes' seeds.
"""

from __future__ import annotations

import ray

from corn_drake.rl.workers.cluster import WorkerBase, worker_options


@ray.remote(num_cpus=1)
class OutcomeChunkWorker(WorkerBase):
    def __init__(self, collection, library):
        import torch

        from corn_drake.rl.workers.cluster import library_here

        # One core per worker: the per-state network calls are too small to gain from more.
        torch.set_num_threads(1)
        self.collection = collection
        self.objects = library_here(library)
        self.envs = {}  # one env per object, as one process keeps them

    def collect(self, first: int, last: int):
        from corn_drake.rl.primitive.outcome.collect import collect_chunk

        return collect_chunk(self.collection, first, last, self.envs, self.objects)


def collect_on_workers(collection, library, workers: int, done) -> None:
    """Collects `collection.chunks` on `workers` Ray workers (Ray started by the caller), the
    objects packed in `library` (cluster.pack_objects); `done(first, arrays, rows)` runs in the
    driver as each chunk ends."""
    from corn_drake.rl.workers.cluster import check_room, worker_cpus
    from corn_drake.rl.workers.job_pool import run_on_pool

    cpus = worker_cpus(workers)
    check_room(workers, cpus, "outcome workers")
    packed, shared = ray.put(library), ray.put(collection)

    def spawn():
        return OutcomeChunkWorker.options(**worker_options(cpus)).remote(shared, packed)

    run_on_pool(spawn, workers, cpus, collection.chunks, lambda w, job: w.collect.remote(*job),
                lambda job, result: done(job[0], *result), "outcome",
                lambda job: f"episodes {job[0]}-{job[1] - 1}")
