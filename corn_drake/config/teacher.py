"""The teacher rollout diagram's config (base: diagrams/teacher_rollout.yaml).

No `from __future__ import annotations`: yaml_load_typed needs real types on the fields.
"""

import dataclasses as dc

from corn_drake.config.plumbing.bounds import check_bounds, relation
from corn_drake.config.scene import ControllerConfig, RandomizationConfig, SceneConfig
from corn_drake.config.task import TaskConfig
from corn_drake.contract import TABLE_TOP_Z


def _holds_table_top(low, high, table_size) -> bool:
    """Whether the workspace box [low, high) holds the table's top (the table is centred on the
    world's xy origin, its top at TABLE_TOP_Z): every object start lies on it (tasks/sampling.py
    draws starts within 95 % of it), so a workspace that leaves part of it out ends episodes at
    their first step."""
    half = [table_size[0] / 2, table_size[1] / 2]
    return (all(low[i] <= -half[i] and half[i] < high[i] for i in range(2))
            and low[2] <= TABLE_TOP_Z < high[2])


def _on_table(goal, half: float) -> bool:
    return -half <= goal[0] and goal[1] <= half


@dc.dataclass
class TeacherDiagramConfig:
    scene: SceneConfig = dc.field(default_factory=SceneConfig)
    randomization: RandomizationConfig = dc.field(default_factory=RandomizationConfig)
    controller: ControllerConfig = dc.field(default_factory=ControllerConfig)
    task: TaskConfig = dc.field(default_factory=TaskConfig)
    seed: int = 0
    # Range checks (config/plumbing/bounds.py), and the relations between the scene and the task, which
    # only this config holds both of: the workspace holds the table top the objects start on,
    # and every goal lies over the table (a goal off it is one no push can reach).
    BOUNDS = {"seed": "seed"}
    RELATIONS = (
        relation("task.workspace_low",
                 "<= the table top's low corner and task.workspace_high above its high corner "
                 "(table {scene.table_size} centred on xy 0, top at z " f"{TABLE_TOP_Z}; "
                 "task.workspace_high {task.workspace_high})",
                 _holds_table_top, "task.workspace_high", "scene.table_size"),
        relation("task.goal_x", "over the table, within +- half of {scene.table_size}[0]",
                 lambda g, size: _on_table(g, size[0] / 2), "scene.table_size"),
        relation("task.goal_y", "over the table, within +- half of {scene.table_size}[1]",
                 lambda g, size: _on_table(g, size[1] / 2), "scene.table_size"),
    )

    def check(self) -> None:
        """InputError naming the first field no episode could be built from (object, size
        randomization, task ranges). Commands call it before they write a run's config, so a
        bad value is refused up front instead of failing the run at its first reset."""
        check_bounds(self)
        self.scene.object.check()
        self.randomization.check()
        self.task.check()
