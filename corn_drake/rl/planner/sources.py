"""Where the 6D expert's candidate primitives come from: one function per source, registered in
SOURCES under the names config/choices.PLANNER_SOURCES lists.

A source is made once per evaluation from the settings (`make(planner, primitive, task)`) and
then called at every node the search expands: `propose(env, obs, rng) -> [Candidate]`, from the
env's state at that node (its observation `obs`; `rng` the episode's generator, drawn from in
the order the search expands, so an episode's search is the same on a rerun).

  policy   a learned primitive run's own candidates (planner.policy names it, any run folder
           `evaluate --run` takes): its greedy choice, its actor's motion at every other usable
           location, and planner.random_motions uniform motions at every usable location
           (rl/primitive/outcome/lookahead.candidate_primitives); ~30 per state for the shipped
           full6d_outcome run;
  push, turn, topple   the analytic kinds of rl/planner/kinds.py, planner.per_kind each.

A new source is one function here that returns such a `propose`, added to SOURCES and to
PLANNER_SOURCES.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from corn_drake.errors import InputError
from corn_drake.rl.envs.branching import Candidate
from corn_drake.rl.planner.kinds import KINDS, Scene
from corn_drake.systems.control.primitive_executor import reachable_from_above

Propose = Callable[[object, dict, np.random.Generator], list[Candidate]]


def policy_run_folder(name: str) -> Path:
    """The run folder planner.policy names: as given (relative to the working folder), else a
    models/... path in the shipped models folder (so the default names the shipped run from
    any working folder and in an installed package)."""
    from corn_drake.package_data import models_dir

    path = Path(name)
    if path.exists():
        return path
    if not path.is_absolute() and path.parts[:1] == ("models",) and \
            (models_dir().joinpath(*path.parts[1:])).exists():
        return models_dir().joinpath(*path.parts[1:])
    raise InputError(f"planner.policy: no run folder {name} (give a primitive run folder, "
                     "e.g. models/weights/full6d_outcome)")


def load_policy(name: str, primitive, task):
    """The PrimitiveAgent of run folder `name`, aimed at the planner's executor settings and
    task (an outcome-model chooser predicts the evaluated task's reward)."""
    from corn_drake.rl.primitive.agent import load_primitive_run
    from corn_drake.run_folders.config_file import run_kind

    folder = policy_run_folder(name)
    kind = run_kind(str(folder))
    if kind != "primitive":
        raise InputError(f"planner.policy: {name} is a {kind} run; the policy source proposes "
                         "with a contact-primitive run (`train --policy primitive`)")
    _, agent, _ = load_primitive_run(folder)
    agent.primitive_config, agent.task = primitive, task
    return agent


def policy_source(planner, primitive, task) -> Propose:
    from corn_drake.rl.primitive.outcome.lookahead import candidate_primitives

    agent = load_policy(planner.policy, primitive, task)

    def propose(env, obs, rng):
        choice = agent.choose(obs)
        return [Candidate("policy", point, motion, location=location)
                for location, point, motion in
                candidate_primitives(choice, planner.random_motions, rng)]
    return propose


def kind_source(kind: str):
    def make(planner, primitive, task) -> Propose:
        def propose(env, obs, rng):
            cloud = np.asarray(obs["cloud"], float)
            normals = np.asarray(obs["normals"], float)
            lengths = np.maximum(np.linalg.norm(normals, axis=1), 1e-9)
            reachable = reachable_from_above(cloud[:, 2], normals[:, 2] / lengths, primitive)
            scene = Scene.of(cloud, normals, env.object_pose(), env.episode.goal_pose,
                             primitive.push_distance, reachable)
            return KINDS[kind](scene)[:planner.per_kind]
        return propose
    return make


SOURCES = {"policy": policy_source, **{kind: kind_source(kind) for kind in KINDS}}


def make_sources(planner, primitive, task) -> list[Propose]:
    """The proposers of planner.sources, in that order."""
    return [SOURCES[name](planner, primitive, task) for name in planner.sources]


def propose_all(sources: list[Propose], env, obs, rng) -> list[Candidate]:
    """Every source's candidates at the env's state, in the sources' order."""
    return [c for propose in sources for c in propose(env, obs, rng)]
