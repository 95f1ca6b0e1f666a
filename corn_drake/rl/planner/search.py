"""The 6D expert: at every decision a beam search over simulated primitives from the env's own
state (snapshot / restore), whose candidates come from planner.sources (rl/planner/sources.py);
it executes the first primitive of the best sequence and searches again from where it landed.

Privileged: it knows the object (its mesh in the simulator, mass, friction, the goal), so it is
the teacher whose labels a learned policy is fitted to, not a deployable policy; its reports
say `privileged: true`.

The search (PlannerConfig's depth D, beam B, discount g; every node expanded through the one
expansion rl/envs/branching.simulate):
  - the root's candidates are simulated; at depth 1 the one with the most reward is executed;
  - otherwise the B root children with the most reward are valued
        value(n) = r(n) + g x max over n's children c of value(c)
    where n's children are the candidates proposed at the state n reached, simulated from it,
    and only the B most rewarding of them are valued further (a child at the last level, or
    one whose episode ended, is valued by its reward alone); the most valuable of the B is
    executed (the first on a tie, so the one with the higher reward).
A decision costs C + B C + B^2 C + ... (D terms) simulated primitives for C candidates per
state. Why a beam valued by reward: every node costs one simulated primitive (~0.3 s of CPU),
so the cost must be fixed by the settings; the reward is the one the learned candidates were
trained on; and this exact search, with the shipped full6d_outcome run's candidates, made
18 / 20 and 30 / 40 of the first fixed full6d episodes where one step made 13 / 20 and 21 / 40
(docs/results/planner/README.md). Nothing is reused between decisions: the next decision
proposes anew from the state reached, so each is the same function of its state and the
episode's generator (what a label records).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from corn_drake.config.planner import PlannerConfig
from corn_drake.config.primitive import PrimitiveConfig
from corn_drake.errors import InputError
from corn_drake.rl.envs.branching import Branch, best, simulate
from corn_drake.rl.planner.sources import make_sources, propose_all

# The policy source's locations per state at most: the encoder's patches (the spec sheet's 16).
LOCATIONS = 16
# A label's reward and value: enough digits for a ranking, few enough for a compact file.
LABEL_DIGITS = 5
# The object's pose at a labelled state ([p, q_wxyz]): a micrometre rebuilds its observation
# (rl/imitation/dataset.py); replaying the executed primitives does not land there exactly.
POSE_DIGITS = 6


class Planner:
    """Chooses and executes one primitive per `act(env, obs)` on a PrimitiveEnv with no policy
    inside; `reset(seed)` before each episode."""

    def __init__(self, config: PlannerConfig, sources: list):
        config.check()
        self.config, self.sources = config, sources
        self.decisions: list[dict] = []
        self.rng = np.random.default_rng(0)
        self.simulated = 0

    def reset(self, seed: int) -> None:
        """A new episode: the candidates' random draws restart from `seed`."""
        self.rng, self.decisions = np.random.default_rng(seed), []

    def _expand(self, env, start, obs) -> list[Branch]:
        env.restore(start)  # the sources may read the env (the object's pose) as well as obs
        candidates = propose_all(self.sources, env, obs, self.rng)
        self.simulated += len(candidates)
        return simulate(env, start, candidates) if candidates else []

    def _beam(self, branches: list[Branch]) -> list[int]:
        """The indices of the `beam` branches with the most reward (stable on ties)."""
        return sorted(range(len(branches)), key=lambda i: -branches[i].reward)[:self.config.beam]

    def _value(self, env, branch: Branch, levels: int, record: list | None = None) -> float:
        """`branch`'s reward plus the discounted best value `levels` levels below it; given
        `record`, the state `branch` reached and its children's rewards are appended to it (a
        root candidate's next state: more labelled states at no cost, see `child_labels`)."""
        if branch.done or levels == 0:
            return branch.reward
        children = self._expand(env, branch.snapshot, branch.step[0])
        if record is not None and children:
            record.append(child_labels(branch, children))
        if not children:  # no usable contact there: nothing more to add
            return branch.reward
        if levels == 1:
            below = max(c.reward for c in children)
        else:
            below = max(self._value(env, children[i], levels - 1) for i in self._beam(children))
        return branch.reward + self.config.discount * below

    def search(self, env, obs) -> tuple[dict, Branch]:
        """Searches from the env's state (`obs` its observation) and returns (the decision: what
        was chosen, what every root candidate earned and was worth, what the search cost; the
        chosen root branch). The env is left in some simulated state: restore a snapshot (the
        branch's, to execute the choice) before stepping it again."""
        started, self.simulated = time.process_time(), 0
        pose = [round(float(v), POSE_DIGITS) for v in env.object_pose()]
        first = self._expand(env, env.snapshot(), obs)
        if not first:
            raise InputError("planner: no candidate primitive at this state (no usable contact "
                             "location for any of planner.sources)")
        children: list[dict] = []
        if self.config.depth == 1:
            chosen, values = best(first), {}
        else:
            values = {}
            for i in self._beam(first):
                before = len(children)
                values[i] = self._value(env, first[i], self.config.depth - 1, children)
                for child in children[before:]:
                    child["root"] = i
            chosen = max(values, key=lambda i: values[i])  # the first of the beam on a tie
        branch = first[chosen]
        decision = {"source": branch.candidate.source, "reward": branch.reward,
                    "value": values.get(chosen, branch.reward), "chosen": chosen,
                    "simulated": self.simulated,
                    "cpu_seconds": time.process_time() - started, "candidates": len(first),
                    "labels": [label_of(b, values.get(i)) for i, b in enumerate(first)],
                    "executed": executed(branch.candidate), "pose": pose,
                    "children": children}
        return decision, branch

    def act(self, env, obs) -> tuple:
        """search, then the chosen primitive executed: leaves the env after it and returns that
        step's (obs, reward, terminated, truncated, info); info["planner"] is the decision."""
        decision, branch = self.search(env, obs)
        env.restore(branch.snapshot)
        self.decisions.append(decision)
        obs, reward, terminated, truncated, info = branch.step
        return obs, reward, terminated, truncated, dict(info, planner=decision)


def label_of(branch: Branch, value: float | None) -> list:
    """One root candidate as a label row: [source, point, location, m_x, m_y, m_z, reward,
    value (None where the search did not value it: outside the beam)]."""
    c = branch.candidate
    return [c.source, c.point, c.location, *(round(float(m), 4) for m in c.motion),
            round(branch.reward, LABEL_DIGITS),
            None if value is None else round(float(value), LABEL_DIGITS)]


def child_labels(branch: Branch, children: list[Branch]) -> dict:
    """The state a root candidate of the beam reached, as a labelled state: the object's pose
    there and a label row per candidate proposed there with the reward it earned (its value is
    not known: the search stops one level on). Four of these per decision at the default beam
    make five labelled states per search instead of one."""
    return {"pose": [round(float(v), POSE_DIGITS) for v in branch.pose],
            "labels": [label_of(c, None) for c in children]}


def executed(candidate) -> dict:
    """The executed primitive exactly (JSON keeps a float's every digit), so a labelled
    episode can be replayed to the states its labels describe: the point, the motion and the
    exact aim where there was one."""
    out = {"point": candidate.point, "motion": [float(m) for m in candidate.motion]}
    if candidate.aim is not None:
        out["aim"] = [[float(v) for v in part] for part in candidate.aim]
    return out


# The label rows' columns (label_of), written once in a labels file's header.
LABEL_COLUMNS = ["source", "point", "location", "motion_x", "motion_y", "motion_z", "reward",
                 "value"]


def budget(config: PlannerConfig, candidates: int) -> int:
    """The most primitives one decision simulates with `candidates` per state."""
    return candidates * sum(config.beam ** level for level in range(config.depth))


@dataclass
class PlannerPolicy:
    """What `--run planner` loads: the search's and the executor's settings; `planner(task)`
    makes the Planner (its sources loaded once)."""
    config: PlannerConfig
    primitive: PrimitiveConfig
    kind: str = "planner"
    facts: dict = field(default_factory=dict)

    def planner(self, task) -> Planner:
        return Planner(self.config, make_sources(self.config, self.primitive, task))

    def candidates_per_state(self) -> int:
        """The most candidates one state can be offered: at each of the policy's locations its
        actor's motion and random_motions more, and per_kind of each analytic kind."""
        return sum(LOCATIONS * (1 + self.config.random_motions) if name == "policy"
                   else self.config.per_kind for name in self.config.sources)

    def describe(self) -> dict:
        return {"privileged": True, "planner": dataclasses.asdict(self.config),
                "primitive": dataclasses.asdict(self.primitive),
                "budget_per_decision": budget(self.config, self.candidates_per_state())}
