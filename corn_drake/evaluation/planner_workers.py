"""The 6D expert's episodes over Ray workers (`evaluate --run planner --workers N`, `label
--workers N`, local cores or a cluster with --ray-address): each worker plays whole episodes
(planner_episodes.play) and hands back the row and its labels; the driver appends them as they
come, so the rows file resumes and merges exactly as one process's would. The objects reach a
cluster's nodes through the object store (rl/workers/cluster.pack_objects: no node reads the
driver's disk). A worker that dies is replaced and its episode given to another: the episode is
played again from its seed, so nothing of it is lost or doubled.
"""

from __future__ import annotations

import ray

from corn_drake.rl.workers.cluster import WorkerBase, worker_options


@ray.remote(num_cpus=1)
class PlannerEpisodeWorker(WorkerBase):
    def __init__(self, policy, cfg, labeller_facts: dict | None, library):
        import torch

        from corn_drake.evaluation.planner_play import labeller_of
        from corn_drake.rl.workers.cluster import library_here

        torch.set_num_threads(1)  # one core per worker: the search is one process's work
        self.library = library_here(library) if library is not None else None
        self.policy, self.cfg = policy, cfg
        self.planner = policy.planner(cfg.task)
        self.labeller = (labeller_of(labeller_facts, policy.primitive, cfg.task)
                         if labeller_facts else None)
        self.env, self.object_id = None, None

    def play(self, k: int, object_id: str, spec, seed: int) -> dict:
        """Episode k's row (its labels under "labels"), as planner_episodes.evaluate_planner
        writes it; `spec` None: the object is read from the worker's copy of the library."""
        from corn_drake.assets.library import load_object_spec
        from corn_drake.evaluation.planner_play import play
        from corn_drake.rl.envs.primitive_env import PrimitiveEnv

        if object_id != self.object_id:  # one env alive per worker
            spec = spec if spec is not None else load_object_spec(self.library, object_id)
            self.env = PrimitiveEnv(self.cfg, self.policy.primitive, spec)
            self.object_id = object_id
        return {"episode": k, "object": object_id, "seed": seed,
                **play(self.env, self.planner, seed, self.labeller)}


def play_on_workers(jobs: list[tuple], policy, cfg, labeller_facts, library, workers: int,
                    done):
    """Plays `jobs` [(k, object id, spec or None, seed)] on `workers` Ray workers (Ray started
    by the caller), calling `done(row)` in the driver as each episode ends."""
    from corn_drake.rl.workers.cluster import check_room, worker_cpus
    from corn_drake.rl.workers.job_pool import run_on_pool

    cpus = worker_cpus(workers)
    check_room(workers, cpus, "planner workers")
    packed = ray.put(library)

    def spawn():
        return PlannerEpisodeWorker.options(**worker_options(cpus)).remote(
            policy, cfg, labeller_facts, packed)

    run_on_pool(spawn, workers, cpus, jobs, lambda w, job: w.play.remote(*job),
                lambda job, row: done(row), "planner", lambda job: f"episode {job[0]}")
