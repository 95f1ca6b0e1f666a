"""The teacher rollout diagram's config (base: diagrams/teacher_rollout.yaml).

No `from __future__ import annotations`: yaml_load_typed needs real types on the fields.
"""

import dataclasses as dc

from corn_drake.config.bounds import check_bounds
from corn_drake.config.scene import ControllerConfig, RandomizationConfig, SceneConfig
from corn_drake.config.task import TaskConfig


@dc.dataclass
class TeacherDiagramConfig:
    scene: SceneConfig = dc.field(default_factory=SceneConfig)
    randomization: RandomizationConfig = dc.field(default_factory=RandomizationConfig)
    controller: ControllerConfig = dc.field(default_factory=ControllerConfig)
    task: TaskConfig = dc.field(default_factory=TaskConfig)
    seed: int = 0

    def check(self) -> None:
        """InputError naming the first field no episode could be built from (object, size
        randomization, task ranges). Commands call it before they write a run's config, so a
        bad value is refused up front instead of failing the run at its first reset."""
        check_bounds(self)
        self.scene.object.check()
        self.randomization.check()
        self.task.check()
