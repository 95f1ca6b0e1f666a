"""Whole jobs on a pool of Ray workers, a dead worker replaced and its job given to another:
the loop the 6D expert's episodes (evaluation/planner_workers.py) and the outcome data's chunks
(outcome_workers.py) share. A job depends only on what it names (an episode's seed, a chunk's
episodes), so playing it again on a new worker loses or doubles nothing."""

from __future__ import annotations

import ray


def run_on_pool(spawn, workers: int, cpus: float, jobs: list, submit, done, name: str,
                describe) -> None:
    """Runs `jobs` on min(`workers`, len(jobs)) workers of `cpus` CPUs made by `spawn()`, one
    job per worker at a time: `submit(worker, job)` starts it (an object ref), `done(job,
    result)` runs in the driver as each ends. A worker that dies is replaced and its job
    ("`describe(job)`") put first in the queue again, said in one line naming the `name`
    worker. When the live nodes have no room for the replacement (its node was lost), the
    others go on without it, said in one line; NoRoomForWorkers when none is left."""
    from corn_drake.rl.workers.cluster import NoRoomForWorkers, death_reason, spawn_replacement

    pool = [spawn() for _ in range(min(workers, len(jobs)))]
    pending, running = list(jobs), {}
    while pending or running:
        busy = {i for i, _ in running.values()}
        for i, worker in enumerate(pool):
            if pending and worker is not None and i not in busy:
                job = pending.pop(0)
                running[submit(worker, job)] = (i, job)
                busy.add(i)
        ready, _ = ray.wait(list(running), num_returns=1)
        i, job = running.pop(ready[0])
        try:
            result = ray.get(ready[0])
        except (ray.exceptions.RayActorError, ray.exceptions.ActorUnavailableError) as error:
            pending.insert(0, job)
            said = f"{name} worker {i} died ({death_reason(error)})"
            try:
                spawn_replacement(name, pool, i, cpus, spawn)
            except NoRoomForWorkers:
                pool[i] = None
                left = sum(w is not None for w in pool)
                if not left:
                    raise
                print(f"{said}: no room for a replacement, {describe(job)} goes to the other "
                      f"{left}", flush=True)
                continue
            print(f"{said}: {describe(job)} goes to a new worker", flush=True)
            continue
        done(job, result)
