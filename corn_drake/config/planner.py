"""The 6D expert's settings (`corn-drake evaluate --run planner --set planner.FIELD=VALUE`): a
beam search over simulated primitives (rl/planner/search.py) whose candidates come from
`sources` (rl/planner/sources.py).

PlannerRunConfig is what `--run planner` evaluates: the env (the task's primitive env), the
executor (`primitive.*`) and the search (`planner.*`), so `--set` reaches all three through the
one path every config takes (config/overrides.apply_sets), checked by their bounds and
relations before any episode.

The defaults are the calibrated expert: the shipped full6d_outcome run's candidates (its actor's
motion at every usable location plus 2 uniform motions each), depth 2, beam 4, a first
primitive valued r1 + 0.9 max r2 (docs/results/planner/README.md: gate A on the first 40
episodes, and the ablation of the analytic kinds beside them: no measured gain, so not in the
default).

No `from __future__ import annotations`: yaml_load_typed needs real types on the fields.
"""

import dataclasses as dc

from corn_drake.config.plumbing.bounds import check_bounds, relation, subset_of
from corn_drake.config.choices import PLANNER_SOURCES
from corn_drake.config.primitive import PrimitiveConfig
from corn_drake.config.teacher import TeacherDiagramConfig

# The shipped run the policy source proposes with, by default (models/weights/).
DEFAULT_POLICY_RUN = "models/weights/full6d_outcome"


@dc.dataclass
class PlannerConfig:
    """Per decision the search simulates the root's candidates, then for each of the `beam`
    best of them (by reward) the next state's candidates, and so on `depth` levels down; a
    first primitive's value is its reward plus `discount` x the best value one level below
    (its own reward alone where the episode ended)."""
    BOUNDS = {"sources": subset_of(PLANNER_SOURCES), "policy": "text",
              "random_motions": ">= 0", "per_kind": ">= 1", "depth": "[1, 4]",
              "beam": ">= 1", "discount": "[0, 1]"}
    RELATIONS = (
        relation("sources", "non-empty", lambda sources: len(sources) > 0),
        relation("policy", "a run folder when {sources} holds policy",
                 lambda policy, sources: "policy" not in sources or bool(policy), "sources"),
    )
    sources: list[str] = dc.field(default_factory=lambda: ["policy"])
    # The primitive run whose candidates the `policy` source proposes: a run folder, as
    # `evaluate --run` takes one (relative to the working folder, or the checkout's models/).
    policy: str = DEFAULT_POLICY_RUN
    # Uniform motions in [-1, 1]^3 tried at every usable location beside the actor's own.
    random_motions: int = 2
    # Candidates per analytic kind (push, turn, topple), best first.
    per_kind: int = 2
    depth: int = 2
    beam: int = 4
    discount: float = 0.9

    def check(self) -> None:
        check_bounds(self, "planner.")


# The executor settings the planner runs with unless --set primitive.* says otherwise: the
# shipped full6d_outcome run's (models/weights/full6d_outcome/config.yaml; the rest are
# PrimitiveConfig's defaults), so the expert and that policy run the same primitives.
SHIPPED_PRIMITIVE = {"approach_steps": 30, "max_primitives": 15}


@dc.dataclass
class PlannerRunConfig:
    """What `--run planner` runs: the env, the executor and the search."""
    env: TeacherDiagramConfig = dc.field(default_factory=TeacherDiagramConfig)
    primitive: PrimitiveConfig = dc.field(
        default_factory=lambda: PrimitiveConfig(**SHIPPED_PRIMITIVE))
    planner: PlannerConfig = dc.field(default_factory=PlannerConfig)

    def check(self) -> None:
        check_bounds(self)
