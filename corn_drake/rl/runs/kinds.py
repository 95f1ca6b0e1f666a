"""The kinds of run `--run` names, one class each, in one registry (RUN_KINDS).

Each kind declares how it is recognised (a folder's config.yaml, run_folders.config_file.run_kind,
or a name such as `scripted`), loaded (`load`), configured for `--task` / `--set`
(`configure`), which of evaluate's per-kind flags it takes (FLAGS, RECORDS, CHECKPOINTS), what
it adds to a report (`report_fields`), which episode runner plays it (RUNNER), what `gallery`
paints on its cloud (PAINTS) and how `ship` packs it (PACK). `evaluate`, `gallery`, `ship`,
`label`, `demo` and the bench read these instead of testing the kind's name; a new kind is one
class here and one entry in RUN_KINDS. `load_any_run` loads a run of any kind, `require_kind`
one of a kind a command needs (`distill` a teacher, `collect-outcomes` a primitive run).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from corn_drake.errors import InputError
from corn_drake.rl.runs.loaded import LoadedRun


class TeacherRun(LoadedRun):
    NAME = "train"
    WHAT = "a dense PPO teacher run (`corn-drake train`)"
    CHECKPOINTS = True
    FLAGS = frozenset({"attention", "stochastic"})
    PAINTS = "attention"
    PACK = "teacher"

    @classmethod
    def load(cls, run: str, checkpoint: str = "") -> "TeacherRun":
        from corn_drake.rl.ppo.teacher_runs import load_run_with_step

        cfg, agent, steps = load_run_with_step(run, checkpoint)
        return cls(run, cfg, agent, cfg.policy, steps, agent.checkpoint_file, Path(run))

    def configure(self, task, sets):
        from corn_drake.config.plumbing.diagram_files import replace_task
        from corn_drake.config.plumbing.overrides import apply_sets, config_changes

        run_cfg = replace_task(self.config, task) if task is not None else self.config
        run_cfg = apply_sets(run_cfg, sets, only="env")
        return run_cfg, config_changes(self.config, run_cfg)


class StudentRun(LoadedRun):
    NAME = "distill"
    WHAT = "a DAgger student run (`corn-drake distill`)"
    FLAGS = frozenset({"perception", "stochastic"})
    PACK = "student"
    PERCEIVES = True

    @classmethod
    def load(cls, run: str, checkpoint: str = "") -> "StudentRun":
        from corn_drake.rl.checkpoints import load_student_run_with_step

        cfg, agent, steps = load_student_run_with_step(run)
        return cls(run, cfg, agent, "student", steps, agent.checkpoint_file, Path(run))

    def configure(self, task, sets):
        """A student takes `--task` and `--set` in its student diagram's teacher part, as a
        teacher's env does."""
        from corn_drake.config.plumbing.diagram_files import replace_task
        from corn_drake.config.plumbing.overrides import apply_sets, config_changes
        from corn_drake.config.training import TrainConfig

        base = TrainConfig(env=self.config.env.teacher)
        run_cfg = replace_task(base, task) if task is not None else base
        run_cfg = apply_sets(run_cfg, sets, only="env")
        return run_cfg, config_changes(base, run_cfg)

    def evaluated_env(self, teacher_env, perception: str | None):
        """A student's diagram config around the evaluated `teacher_env`, seen through the full
        perception chain (geometric segmentation, ICP tracking, observation noise) whatever it
        was trained with unless `perception` names another segmentation; and the report's
        fields on it (trained_perception, observation_noise)."""
        student_cfg = self.config.env
        trained_with = student_cfg.segmentation.mode
        student_cfg = dataclasses.replace(
            student_cfg, teacher=teacher_env,
            segmentation=dataclasses.replace(student_cfg.segmentation,
                                             mode=perception or "geometric"))
        student_cfg.check()
        return student_cfg, {"trained_perception": trained_with,
                             "observation_noise": dataclasses.asdict(student_cfg.observation)}


class PrimitiveRun(LoadedRun):
    NAME = "primitive"
    WHAT = "a contact-primitive run (`corn-drake train --policy primitive`)"
    CHECKPOINTS = True
    HINTS = {"attention": "it has no cross-attention; its Meshcat view (--record, --keep-open) "
                          "shows its contact point, push and location scores",
             "stochastic": "it chooses greedily"}
    PAINTS = "location scores"
    PACK = "primitive"

    @classmethod
    def load(cls, run: str, checkpoint: str = "") -> "PrimitiveRun":
        from corn_drake.rl.checkpoints import agent_weights_folder
        from corn_drake.rl.primitive.agent import load_primitive_run

        cfg, agent, steps = load_primitive_run(run, checkpoint)
        # A shipped outcome-model folder reads a sibling folder's actor and critic.
        return cls(run, cfg, agent, cfg.policy, steps, agent.checkpoint_file,
                   agent_weights_folder(run, cfg.agent_weights))

    def configure(self, task, sets):
        """The executor's and outcome settings are the policy's own, so `--set` reaches them
        too (e.g. primitive.success_at_rest=true), and the agent is re-aimed at the result."""
        from corn_drake.config.plumbing.diagram_files import primitive_run_on
        from corn_drake.config.plumbing.overrides import config_changes

        run_cfg = primitive_run_on(self.config, task, sets)
        self.agent.primitive_config = run_cfg.primitive
        # An outcome-model chooser predicts the evaluated task's reward and success.
        self.agent.task = run_cfg.env.task
        return run_cfg, config_changes(self.config, run_cfg)

    def report_fields(self) -> dict:
        fields = {**super().report_fields(), "env_steps_unit": "primitives",
                  "chooser": self.config.chooser}
        chooser = self.agent.outcome_chooser
        if chooser is not None:
            # A learned 6D chooser (rl/imitation/) wraps the outcome model: both said.
            inner = getattr(chooser, "inner", None)
            fields["outcome_model"] = (inner or chooser).facts
            if inner is not None:
                fields["chooser_value"] = chooser.facts
        return fields


class ReferenceRun(LoadedRun):
    NAME = "reference"
    WHAT = "a reference controller"
    DETAIL = "scripted: a straight-line pusher; still: zero action"
    NAMES = ("scripted", "still")
    # The controller class (rl/scripted.py) each name runs.
    CONTROLLERS = {"scripted": "ScriptedPushAgent", "still": "HoldStillAgent"}

    @classmethod
    def load(cls, run: str, checkpoint: str = "") -> "ReferenceRun":
        return cls(run, None, None, run)

    def configure(self, task, sets):
        """A reference has no run: --task chooses its task (default the paper's 6D task), --set
        changes that task; its controller is made for the result."""
        from corn_drake.config.plumbing.diagram_files import load_teacher_config
        from corn_drake.config.plumbing.overrides import apply_sets, config_changes
        from corn_drake.config.training import TrainConfig
        from corn_drake.rl import scripted

        base = TrainConfig(env=load_teacher_config(task))
        run_cfg = apply_sets(base, sets, only="env")
        self.agent = getattr(scripted, self.CONTROLLERS[self.run])(run_cfg.env.controller)
        return run_cfg, config_changes(base, run_cfg)

    def report_fields(self) -> dict:
        return {}


class PlannerRun(LoadedRun):
    NAME = "planner"
    WHAT = "the 6D expert"
    DETAIL = "a privileged search over simulated primitives; --set planner.*"
    NAMES = ("planner",)
    FLAGS = frozenset({"workers", "ray_address"})
    RECORDS = False  # its search steps the env outside a diagram recording
    RUNNER = "planner"

    @classmethod
    def load(cls, run: str, checkpoint: str = "") -> "PlannerRun":
        return cls(run, None, None, run)

    def configure(self, task, sets):
        """env (--task, task.* ...), primitive.* and planner.* through the common path; the
        default task is the paper's 6D task on the primitive policies' env layer."""
        from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
        from corn_drake.config.plumbing.overrides import apply_sets, config_changes
        from corn_drake.config.planner import PlannerRunConfig
        from corn_drake.rl.planner.search import PlannerPolicy

        base = PlannerRunConfig(env=load_primitive_env_config(task or "full6d"))
        run_cfg = apply_sets(base, sets, only=("env", "primitive", "planner"))
        run_cfg.check()
        self.agent = PlannerPolicy(run_cfg.planner, run_cfg.primitive)
        return run_cfg, config_changes(base, run_cfg)

    def report_fields(self) -> dict:
        return self.agent.describe() if self.agent is not None else {}

    def card_run(self) -> str | None:
        """The run the `policy` source proposes with (after configure): its card names the
        library the expert's candidates were learned and measured on; None without that source."""
        if self.agent is None or "policy" not in self.agent.config.sources:
            return None
        return self.agent.config.policy


# Every kind, in the order help texts list them: adding a kind is one class above and its name
# here.
RUN_KINDS: dict[str, type[LoadedRun]] = {k.NAME: k for k in (
    TeacherRun, StudentRun, PrimitiveRun, ReferenceRun, PlannerRun)}


def named_kind(run: str) -> type[LoadedRun] | None:
    """The kind a name such as `scripted` or `planner` stands for, None for a folder path."""
    return next((k for k in RUN_KINDS.values() if run in k.NAMES), None)


def kinds_taking(flag: str) -> list[type[LoadedRun]]:
    """The kinds that take evaluate's per-kind `flag` (its dest)."""
    return [k for k in RUN_KINDS.values() if flag in k.FLAGS]


def run_kind_of(run: str, references: bool = True) -> type[LoadedRun]:
    """The kind of `run`: the one a name such as `scripted` or `planner` stands for (with
    `references`), else the kind of run folder `run` is (run_folders.config_file.run_kind: an
    error naming --run for neither)."""
    from corn_drake.run_folders.config_file import run_kind

    named = named_kind(run) if references else None
    if named is not None:
        return named
    names = [n for k in RUN_KINDS.values() for n in k.NAMES]
    return RUN_KINDS[run_kind(run, or_else=f"one of {', '.join(names)}" if references else "")]


def load_any_run(run: str, checkpoint: str = "", references: bool = True) -> LoadedRun:
    """The run `run` of any kind, loaded as evaluate and ship both take it: its config, its
    agent with the weights of checkpoints/last.pt (prev.pt if need be) or, for a kind that
    keeps them, the kept `checkpoint` file. Without `references` a name such as `scripted` is
    not a run (it is looked for as a run folder)."""
    kind = run_kind_of(run, references)
    if checkpoint and not kind.CHECKPOINTS:
        takers = " or ".join(k.WHAT for k in RUN_KINDS.values() if k.CHECKPOINTS)
        raise InputError(f"--checkpoint {checkpoint} picks one of the kept checkpoints of "
                         f"{takers}; --run {run} is {kind.WHAT}")
    return kind.load(run, checkpoint)


def require_kind(run: str, wanted: str, flag: str = "--run", needs: str = "") -> type[LoadedRun]:
    """The kind of run folder `run` when it is the registry's `wanted` kind (a command that
    reads only one kind: `distill` a teacher, `collect-outcomes` and `fit-outcome` a primitive
    run), else an InputError naming `flag`, what the folder is and what `needs` it."""
    kind = run_kind_of(run, references=False)
    if kind.NAME != wanted:
        raise InputError(f"{flag} {run} is {kind.WHAT}; {needs or 'this command'} reads "
                         f"{RUN_KINDS[wanted].WHAT}")
    return kind
