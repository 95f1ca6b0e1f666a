"""Whole jobs on a pool of Ray workers, a dead worker replaced and its job given to another:
the loop the 6D expert's episodes (evaluation/planner_workers.py) and the outcome data's chunks
(outcome_workers.py) share. A job depends only on what it names (an episode's seed, a chunk's
episodes), so playing it again on a new worker loses or doubles nothing."""

from __future__ import annotations

import ray


def run_on_pool(spawn, workers: int, jobs: list, submit, done, name: str, describe) -> None:
    """Runs `jobs` on min(`workers`, len(jobs)) workers made by `spawn()`, one job per worker
    at a time: `submit(worker, job)` starts it (an object ref), `done(job, result)` runs in the
    driver as each ends. A worker that dies is replaced and its job ("`describe(job)`") put
    first in the queue again, said in one line naming the `name` worker."""
    from corn_drake.rl.workers.cluster import death_reason

    pool = [spawn() for _ in range(min(workers, len(jobs)))]
    pending, running = list(jobs), {}
    while pending or running:
        busy = {i for i, _ in running.values()}
        for i, worker in enumerate(pool):
            if pending and i not in busy:
                job = pending.pop(0)
                running[submit(worker, job)] = (i, job)
                busy.add(i)
        ready, _ = ray.wait(list(running), num_returns=1)
        i, job = running.pop(ready[0])
        try:
            result = ray.get(ready[0])
        except (ray.exceptions.RayActorError, ray.exceptions.ActorUnavailableError) as error:
            print(f"{name} worker {i} died ({death_reason(error)}): {describe(job)} goes to a "
                  "new worker", flush=True)
            pool[i] = spawn()
            pending.insert(0, job)
            continue
        done(job, result)
