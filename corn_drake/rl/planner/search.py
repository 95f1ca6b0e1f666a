"""A planning policy with the simulator as its model: at every decision it simulates candidate
primitives (rl/planner/kinds.py) from the env's own state (snapshot / restore), searches
`depth` primitives deep, executes the first primitive of the best sequence and replans.

Privileged: it knows the object (its mesh in the simulator, mass, friction, the goal), so it is
an upper reference for what these primitives can do, not a deployable policy; its reports say
`privileged: true`.

Why beam search: each node costs one simulated primitive (~0.5-1.5 s of CPU), so the search
must be cheap and its cost known in advance; a beam's cost is fixed by one setting
(per decision at most candidates + (depth - 1) x beam x candidates primitives), it is anytime
(level 1 alone is already the one-step lookahead, every level only refines it), and it needs
no value function, where MCTS would need rollouts or a value estimate to beat it at this budget.
The chosen first primitive's subtree is kept: the next decision starts from exactly the state
the search already reached (restore is exact: tests/test_planner.py), so its first level costs
nothing and each later decision simulates only beam x candidates primitives at depth 2.

A sequence's score is the task's own: success under the task's rule anywhere along it
dominates (SUCCESS); then minus the goal distance in tolerances, position_error /
success_position + orientation_error / success_orientation, at its best node (a replanning
policy keeps whichever prefix is best); leaving the workspace or a failed simulation scores
FAILED.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from corn_drake.config.bounds import check_bounds
from corn_drake.config.primitive import PrimitiveConfig
from corn_drake.errors import InputError
from corn_drake.rl.envs.primitive_env import PrimitiveEnv
from corn_drake.rl.planner.kinds import KINDS, Candidate, propose
from corn_drake.systems.primitive_executor import reachable_from_above

SUCCESS = 1e3
FAILED = -1e3


@dataclass
class PlannerConfig:
    """The planner's budget (`--set planner.FIELD=VALUE`): per decision at most
    per_kind x kinds + (depth - 1) x beam x per_kind x kinds simulated primitives."""
    BOUNDS = {"per_kind": ">= 1", "beam": ">= 1", "depth": "[1, 4]", "kinds": "text"}
    per_kind: int = 2
    beam: int = 3
    depth: int = 2
    kinds: str = "push,turn,topple"  # comma-separated, of rl/planner/kinds.KINDS

    def kind_list(self) -> tuple[str, ...]:
        kinds = tuple(k.strip() for k in self.kinds.split(",") if k.strip())
        unknown = [k for k in kinds if k not in KINDS]
        if unknown or not kinds:
            raise InputError(f"planner.kinds: {self.kinds!r} must name some of "
                             f"{', '.join(KINDS)}, comma-separated")
        return kinds

    def check(self) -> None:
        check_bounds(self, "planner.")
        self.kind_list()


class PlannerEnv(PrimitiveEnv):
    """A PrimitiveEnv whose next step may aim exactly at a candidate's point (a topple: never
    lowered toward push_height), and counts the primitives it simulated."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._exact_aim = None
        self.simulated = 0

    def step_candidate(self, candidate: Candidate):
        self._exact_aim = (candidate.point, candidate.normal) if candidate.exact else None
        try:
            self.simulated += 1
            return self.step({"point": candidate.index, "motion": candidate.motion})
        finally:
            self._exact_aim = None

    def _aim(self, obs: dict, point: int):
        if self._exact_aim is not None:
            return self._exact_aim
        return super()._aim(obs, point)


@dataclass
class Node:
    """A state the search reached: the primitive that led there from its parent, the env's
    snapshot after it, the step's return and its score."""
    candidate: Candidate | None
    snapshot: object
    step: tuple | None
    score: float
    done: bool
    children: list["Node"] | None = None

    def value(self) -> float:
        """The best score along any sequence from here (a replanning policy stops wherever it
        is best; one expanded level more can only raise it)."""
        best = self.score
        for child in self.children or ():
            best = max(best, child.value())
        return best

    def success(self) -> bool:
        return self.score >= SUCCESS


def beam_of(nodes: list[Node], width: int) -> list[Node]:
    """The `width` nodes kept for the next level: the best of each kind first (by score), then
    the best of the rest. Why: a push that turns the object scores worse than a turn at once
    and better after the turn that follows it; a beam of the best scores alone filled with
    turns and never looked behind the push (measured on a box: 15 turns, no progress)."""
    ranked = sorted(nodes, key=lambda n: -n.score)
    firsts, seen = [], set()
    for n in ranked:
        if n.candidate.kind not in seen:
            seen.add(n.candidate.kind)
            firsts.append(n)
    rest = [n for n in ranked if all(n is not f for f in firsts)]
    return (firsts + rest)[:width]


def score_of(step: tuple, task) -> tuple[float, bool]:
    """(score, episode over) of an env step's return (see the module docstring)."""
    _, _, terminated, truncated, info = step
    if "sim_error" in info:
        return FAILED, True
    status = info["status"]
    if status["success"] > 0:
        return SUCCESS, True
    if status["out_of_workspace"] > 0:
        return FAILED, True
    distance = status["position_error"] / task.success_position + \
        status["orientation_error"] / task.success_orientation
    return -float(distance), bool(terminated or truncated)


class Planner:
    """Chooses and executes one primitive per `act(env)` call on a PlannerEnv."""

    def __init__(self, config: PlannerConfig, primitive: PrimitiveConfig, task):
        config.check()
        self.config, self.primitive, self.task = config, primitive, task
        self.kinds = config.kind_list()
        self._root: Node | None = None
        self.decisions: list[dict] = []

    def reset(self) -> None:
        self._root, self.decisions = None, []

    def _candidates(self, env: PlannerEnv, obs: dict) -> list[Candidate]:
        cloud, normals = np.asarray(obs["cloud"], float), np.asarray(obs["normals"], float)
        lengths = np.maximum(np.linalg.norm(normals, axis=1), 1e-9)
        reachable = reachable_from_above(cloud[:, 2], normals[:, 2] / lengths, self.primitive)
        return propose(cloud, normals, env.object_pose(), env.episode.goal_pose,
                       self.primitive.push_distance, reachable, self.kinds,
                       self.config.per_kind)

    def _expand(self, env: PlannerEnv, node: Node) -> None:
        env.restore(node.snapshot)
        obs = node.step[0] if node.step is not None else env._observation()
        node.children = []
        for candidate in self._candidates(env, obs):
            env.restore(node.snapshot)
            step = env.step_candidate(candidate)
            score, done = score_of(step, self.task)
            node.children.append(Node(candidate, env.snapshot(), step, score, done))

    def act(self, env: PlannerEnv) -> tuple:
        """Searches from the env's state, leaves the env after the chosen primitive and returns
        that step's (obs, reward, terminated, truncated, info); info["planner"] says what was
        chosen and what it cost."""
        started, simulated = time.process_time(), env.simulated
        root = self._root
        if root is None or root.snapshot is None:
            root = Node(None, env.snapshot(), None, -np.inf, False)
        frontier = [root]
        for _ in range(self.config.depth):
            level = []
            for node in frontier:
                if node.children is None:
                    self._expand(env, node)
                level += node.children
            if not level or any(n.success() for n in level):
                break
            frontier = beam_of([n for n in level if not n.done], self.config.beam)
            if not frontier:
                break
        if not root.children:
            raise InputError("planner: no candidate primitive (no reachable side point)")
        best = max(root.children, key=lambda n: (n.value(), n.score))
        env.restore(best.snapshot)
        self._root = best
        decision = {"kind": best.candidate.kind, "score": best.score, "value": best.value(),
                    "simulated": env.simulated - simulated,
                    "cpu_seconds": time.process_time() - started,
                    "candidates": len(root.children)}
        self.decisions.append(decision)
        obs, reward, terminated, truncated, info = best.step
        info = dict(info, planner=decision)
        return obs, reward, terminated, truncated, info


def planner_settings(sets: list[str]) -> tuple[PlannerConfig, dict, list[str]]:
    """(PlannerConfig, primitive.* overrides, the other --set items) of `--set` items."""
    config, primitive, rest = PlannerConfig(), {}, []
    fields = {f.name: f.type for f in dataclasses.fields(PlannerConfig)}
    for item in sets:
        key, eq, value = item.partition("=")
        if not eq:
            raise InputError(f"--set {item}: expected KEY=VALUE")
        if key.startswith("planner."):
            name = key[len("planner."):]
            if name not in fields:
                raise InputError(f"--set {key}: the planner has no setting {name!r} (it has "
                                 f"{', '.join(fields)})")
            try:
                config = dataclasses.replace(config, **{name: value if name == "kinds"
                                                        else int(value)})
            except ValueError:
                raise InputError(f"--set {key}={value}: expected a whole number") from None
        elif key.startswith("primitive."):
            primitive[key[len("primitive."):]] = value
        else:
            rest.append(item)
    config.check()
    return config, primitive, rest


# The executor settings the planner runs with unless --set primitive.* says otherwise: the
# shipped full6d_outcome policy's (models/weights/full6d_outcome/config.yaml), so the two are
# compared on the same primitives and the same primitive budget.
SHIPPED_PRIMITIVE = {"approach_steps": 30, "max_primitives": 15}


def primitive_config(overrides: dict) -> PrimitiveConfig:
    import yaml

    values = dict(SHIPPED_PRIMITIVE)
    for name, text in overrides.items():
        if name not in {f.name for f in dataclasses.fields(PrimitiveConfig)}:
            raise InputError(f"--set primitive.{name}: the executor has no such setting")
        values[name] = yaml.safe_load(text)
    config = PrimitiveConfig(**values)
    check_bounds(config, "primitive.")
    return config


@dataclass
class PlannerPolicy:
    """What `--run planner` loads: the settings, and a planner per env."""
    config: PlannerConfig
    primitive: PrimitiveConfig
    kind: str = "planner"
    facts: dict = field(default_factory=dict)

    def describe(self) -> dict:
        return {"privileged": True, "planner": dataclasses.asdict(self.config),
                "primitive": dataclasses.asdict(self.primitive),
                "budget_per_decision": budget(self.config)}


def budget(config: PlannerConfig) -> int:
    """The most primitives one decision simulates (the first; later ones reuse a level)."""
    c = config.per_kind * len(config.kind_list())
    return c + (config.depth - 1) * config.beam * c
