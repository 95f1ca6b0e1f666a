"""The diagram YAML files (diagrams/) and their layers: the teacher's base diagram with a task
overlay, the student's layer on top of a teacher config. Every layer is read by the one loader
(config/plumbing/loader.py) on top of the layer below it, so a layer names only what differs.
"""

import dataclasses as dc
from pathlib import Path

from corn_drake import DIAGRAMS_DIR
from corn_drake.config.plumbing.loader import load_config
from corn_drake.config.student import StudentDiagramConfig
from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.config.training import TrainConfig
from corn_drake.errors import InputError, MissingInputError


BASE_DIAGRAM = DIAGRAMS_DIR / "teacher_rollout.yaml"


TASKS_DIR = DIAGRAMS_DIR / "tasks"


# --- layers 1 and 2: base diagram and task overlay ----------------------------------------------
def available_tasks() -> list[str]:
    return sorted(p.stem for p in TASKS_DIR.glob("*.yaml"))


def task_file(task: str | Path) -> Path:
    """The overlay `--task` names: a task in diagrams/tasks/, or a YAML file's path."""
    path = Path(task)
    if path.suffix in (".yaml", ".yml") or len(path.parts) > 1:
        if not path.is_file():
            raise MissingInputError(f"--task {task}: no such file")
        return path
    named = TASKS_DIR / f"{task}.yaml"
    if not named.is_file():
        raise InputError(f"--task {task}: no such task; the tasks are "
                         f"{', '.join(available_tasks()) or '(none)'} (in {TASKS_DIR}), or give "
                         "a task YAML file's path")
    return named


def load_teacher_config(task: str | Path | None = None) -> TeacherDiagramConfig:
    """The teacher diagram's config: the base diagram (diagrams/teacher_rollout.yaml), with the
    overlay of `task` (a name in diagrams/tasks/ or a YAML file's path, as `--task`) on top;
    None: the base alone, the paper's task. The task's name is the overlay's task.name if it
    sets one, else the file's stem."""
    cfg = load_config(TeacherDiagramConfig, BASE_DIAGRAM)
    if task is None:
        return cfg
    path = task_file(task)
    cfg.task.name = path.stem  # the name unless the overlay sets its own on top
    return load_config(TeacherDiagramConfig, path, defaults=cfg)


PRIMITIVE_LAYER = DIAGRAMS_DIR / "primitive_rollout.yaml"


def load_primitive_env_config(task: str | Path | None = None) -> TeacherDiagramConfig:
    """The contact-primitive policy's env config: load_teacher_config(task) with the primitive
    layer (diagrams/primitive_rollout.yaml) on top."""
    return load_config(TeacherDiagramConfig, PRIMITIVE_LAYER, defaults=load_teacher_config(task))


def replace_task(cfg: TrainConfig, task: str | Path) -> TrainConfig:
    """`cfg` with its env rebuilt from the base and `task`'s overlay. The object(s) stay cfg's:
    they are chosen apart from the task (`train --objects`)."""
    env = load_teacher_config(task)
    env.scene.object = cfg.env.scene.object
    return dc.replace(cfg, env=env)


# --- the student diagram: a layer on top of a teacher config -----------------------------------
STUDENT_BASE_DIAGRAM = DIAGRAMS_DIR / "student_rollout.yaml"


def load_student_config(path: str | Path | None = None,
                        base: StudentDiagramConfig | None = None) -> StudentDiagramConfig:
    """The student layer at `path` (default: the base student diagram, STUDENT_BASE_DIAGRAM)
    read on top of `base` (default: StudentDiagramConfig(), whose teacher part a caller sets to
    a teacher run's env), then checked. `base` is not modified. A missing file, bad YAML, an
    unknown key, a wrong type or a value the diagram cannot run with raises an InputError
    naming the file or field."""
    path = Path(path) if path is not None else STUDENT_BASE_DIAGRAM
    # yaml_load_typed copies `defaults`: the caller's base is left as it was.
    cfg = load_config(StudentDiagramConfig, path, defaults=base or StudentDiagramConfig())
    cfg.check()
    return cfg


def with_primitive_task(base, task: str):
    """A primitive run's config (PrimitiveTrainConfig) on another task: the primitive diagram
    of `task` (a name in diagrams/tasks/ or a YAML file), the run's object or library kept."""
    env = load_primitive_env_config(task)
    env.scene.object = base.env.scene.object
    return dc.replace(base, env=env)


def primitive_run_on(base, task: str | None, sets):
    """A primitive run's config as `evaluate` runs it: `task`'s overlay (None: its own task),
    then the `--set` items (env.* and primitive.* only); a changed executor section is
    range-checked (config/plumbing/bounds.py)."""
    from corn_drake.config.plumbing.bounds import check_bounds
    from corn_drake.config.plumbing.overrides import apply_sets

    cfg = with_primitive_task(base, task) if task is not None else base
    cfg = apply_sets(cfg, sets, only=("env", "primitive"))
    if cfg.primitive != base.primitive:
        check_bounds(cfg.primitive, "primitive.")
    return cfg
