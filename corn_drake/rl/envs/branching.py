"""One expansion of a search over primitives: from one env state, simulate each candidate
primitive and keep what it led to (its reward, the state after it, whether the episode ended).

The one-step lookahead (rl/primitive/outcome/lookahead.py, which labels the outcome models'
data) and the planner's search (rl/planner/search.py, at every depth) both expand through
`simulate`, so a candidate is simulated, scored and snapshotted the same way everywhere and a
search's cost is counted in one place (`Branch` per simulated primitive).

Why a node is scored by the env's own reward: the primitive reward (PrimitiveConfig's
progress_reward x the keypoint distance closed, plus the task's success_reward on success) is
what the learned policies were trained and their outcome models fitted on, and the two-step
search that made 62 / 76 full6d episodes ranks by it (r1 + discount x max r2); a success's
reward dominates any progress.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corn_drake.errors import InputError


@dataclass(frozen=True)
class Candidate:
    """One primitive to try: `source` (who proposed it: "policy" or an analytic kind), `point`
    (the cloud index the env's action names), `motion` ((3,) in [-1, 1], times push_distance),
    `aim` (None: the env's own aim for the point, low_push's; else (point (3,), outward normal
    (3,)) in the world, aimed at exactly: a topple must not be lowered) and `location` (the
    policy's location index, -1 for an analytic kind)."""
    source: str
    point: int
    motion: np.ndarray
    aim: tuple | None = None
    location: int = -1

    def action(self) -> dict:
        return {"point": self.point, "motion": self.motion}

    def describe(self) -> dict:
        return {"source": self.source, "point": self.point, "location": self.location,
                "motion": [round(float(m), 4) for m in self.motion]}


@dataclass
class Branch:
    """What one simulated candidate led to: the env step's (obs, reward, terminated,
    truncated, info), the snapshot after it, the object's pose and stillness then."""
    candidate: Candidate
    step: tuple
    snapshot: object
    pose: np.ndarray
    still: bool

    @property
    def reward(self) -> float:
        return float(self.step[1])

    @property
    def done(self) -> bool:
        """The episode ended with this primitive (success, out of the workspace, a failed
        simulation, or the primitive or period budget spent)."""
        return bool(self.step[2] or self.step[3])

    @property
    def success(self) -> bool:
        return self.step[4].get("status", {}).get("success", 0) > 0


def simulate(env, start, candidates: list[Candidate]) -> list[Branch]:
    """Every candidate simulated from `start` (a snapshot of `env`, a PrimitiveEnv with no
    policy inside), in order; the env is left after the last one."""
    if not candidates:
        raise InputError("search: no candidate primitives (no usable contact location)")
    out = []
    for candidate in candidates:
        env.restore(start)
        step = env.step(candidate.action(), aim=candidate.aim)
        out.append(Branch(candidate, step, env.snapshot(), env.object_pose(),
                          bool(env.object_still())))
    return out


def best(branches: list[Branch]) -> int:
    """The index of the branch with the most reward (the first on a tie: a policy's own
    choice, proposed first, wins ties)."""
    return max(range(len(branches)), key=lambda i: (branches[i].reward, -i))
