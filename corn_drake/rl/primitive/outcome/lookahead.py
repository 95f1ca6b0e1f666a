"""One-step lookahead over contact primitives: simulate every candidate from the env's current
state, keep the one whose primitive earned the most reward.

A diagnostic, not a policy: it uses the simulator (the exact object, its mass and friction) as
a model, which no deployed policy has. What it measures is how far the primitive set itself
can take a task when each primitive is chosen as well as one primitive's outcome allows: if
that is far above the learned policy, the learner is what holds the task back; if it is not,
the primitives are (the primitive results, item 33; `evaluate --run planner --set
planner.depth=1` runs it on the evaluation episodes: rl/planner/). It also
labels the data an outcome model is fitted to (collect.py: every candidate's measured outcome).

The candidates are the learned policy's own: for every location it may use, the motion its
actor gives there, plus `random_motions` motions drawn uniformly from [-1, 1]^3 per location.
So the policy's greedy choice is always among them, and the lookahead's reward per primitive is
never below the greedy one's from the same state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corn_drake.errors import InputError
from corn_drake.rl.envs.branching import Candidate, best, simulate


@dataclass
class LookaheadStep:
    """The chosen candidate's env step, and what was tried."""
    point: int
    motion: np.ndarray
    rewards: np.ndarray  # every candidate's reward, in candidate order
    chosen: int  # index of the chosen candidate
    greedy_reward: float  # the policy's own greedy choice (candidate 0)
    step: tuple  # (obs, reward, terminated, truncated, info) of the chosen primitive
    start: object  # the env's snapshot before any candidate (to take another one instead)
    poses: np.ndarray  # (K, 7) the object's pose [p, q_wxyz] after every candidate
    still: np.ndarray  # (K,) whether the object was still after every candidate
    successes: np.ndarray  # (K,) whether the task's status said success after every candidate


def candidate_primitives(choice: dict, random_motions: int, rng: np.random.Generator
                         ) -> list[tuple[int, int, np.ndarray]]:
    """[(location, cloud point, motion)] from PrimitiveAgent.choose's `choice`: the greedy
    choice first, then the actor's motion at every other usable location, then
    `random_motions` uniform motions at every usable location."""
    if random_motions < 0:
        raise InputError(f"lookahead: random_motions must be >= 0, got {random_motions}")
    usable = np.flatnonzero(choice["usable"])
    greedy, points, motions = int(choice["location"]), choice["candidates"], choice["motions"]
    out = [(greedy, int(choice["point"]), np.asarray(choice["motion"], float))]
    for location in usable:
        if location != greedy:
            out.append((int(location), int(points[location]), np.asarray(motions[location], float)))
    for location in usable:
        for _ in range(random_motions):
            out.append((int(location), int(points[location]), rng.uniform(-1.0, 1.0, 3)))
    return out


def lookahead_step(env, candidates: list[tuple[int, int, np.ndarray]]) -> LookaheadStep:
    """Tries every candidate primitive from `env`'s state (a PrimitiveEnv with no policy inside)
    through the search's one expansion (rl/envs/branching.simulate) and leaves the env in the
    state after the best one (the most reward; the first on a tie, so the greedy choice wins
    ties)."""
    if not candidates:
        raise InputError("lookahead: no candidate primitives (no usable location)")
    start = env.snapshot()
    branches = simulate(env, start, [Candidate("policy", point, np.asarray(motion, float),
                                               location=location)
                                     for location, point, motion in candidates])
    chosen = best(branches)
    env.restore(branches[chosen].snapshot)
    _, point, motion = candidates[chosen]
    rewards = np.array([b.reward for b in branches])
    return LookaheadStep(point=point, motion=motion, rewards=rewards, chosen=chosen,
                         greedy_reward=float(rewards[0]), step=branches[chosen].step,
                         start=start, poses=np.array([b.pose for b in branches]),
                         still=np.array([b.still for b in branches]),
                         successes=np.array([b.success for b in branches]))
