"""A run of any kind, loaded once for whoever acts with it: `evaluate` runs its episodes, `ship`
packs its weights (evaluation/shipping.py).

Four kinds of `--run`: a PPO teacher (`train`), a DAgger student (`distill`), a
contact-primitive policy (`train --policy primitive`, its outcome-model runs included) and a
reference controller named in REFERENCES. `load_any_run` tells them apart and returns a
LoadedRun: the run's own config, its agent in eval mode, which checkpoint file and how many env
steps its weights hold (what a report records, and what `ship` checks a report against), and
`configure`, which applies `--task` / `--set` the way that kind of run takes them. The commands
only parse flags and print.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

# Reference controllers `--run` accepts in place of a run folder (rl/scripted.py).
REFERENCES = {"scripted": "ScriptedPushAgent", "still": "HoldStillAgent"}
# The privileged planning policy (rl/planner/): no run folder, its budget is `--set planner.*`.
PLANNER = "planner"
# The files beside a primitive run's checkpoint that choose for it (an outcome model, a learned
# 6D chooser): part of its weights_hash.
CHOOSER_FILES = ("outcome_model.pt", "chooser_value.pt")


@dataclass
class LoadedRun:
    """What a loaded run is: `kind` ("train", "distill", "primitive" or "reference"), `run` (as
    given), `config` (its own: TrainConfig, DistillConfig or PrimitiveTrainConfig; None for a
    reference until `configure`), `agent` (eval mode; a reference's is made by `configure`),
    `policy` (the report's name for it), and for a run folder `env_steps` and `checkpoint_file`
    (of the weights loaded: prev.pt after a fallback) and `weights_folder` (whose checkpoints/
    holds that file: a shipped outcome folder's sibling, for one that names agent_weights)."""

    kind: str
    run: str
    config: Any
    agent: Any
    policy: str
    env_steps: int | None = None
    checkpoint_file: str | None = None
    weights_folder: Path | None = None

    @property
    def checkpoint_path(self) -> Path:
        """The very file the weights were loaded from."""
        return self.weights_folder / "checkpoints" / self.checkpoint_file

    def weights_hash(self) -> str | None:
        """sha256 over what decides this run's choices: its config.yaml, the checkpoint file its
        weights were loaded from and the chooser's model files beside them (None for a
        reference or the planner). A report records it; `ship` packs only the weights whose
        hash the report it quotes recorded."""
        if self.kind in ("reference", "planner"):
            return None
        return weights_hash(Path(self.run), self.checkpoint_path)

    def report_fields(self) -> dict:
        """What a report of this run records of the weights it measured ({} for a reference):
        `ship` compares env_steps and checkpoint with the weights it packs."""
        if self.kind == "reference":
            return {}
        if self.kind == "planner":
            return self.agent.describe() if self.agent is not None else {}
        fields = {"env_steps": self.env_steps}
        if self.kind == "primitive":  # one decision each, many policy periods
            fields["env_steps_unit"] = "primitives"
        fields["checkpoint"] = self.checkpoint_file
        fields["weights_sha256"] = self.weights_hash()
        if self.kind == "primitive":
            fields["chooser"] = self.config.chooser
            chooser = self.agent.outcome_chooser
            if chooser is not None:
                # A learned 6D chooser (rl/imitation/) wraps the outcome model: both said.
                inner = getattr(chooser, "inner", None)
                fields["outcome_model"] = (inner or chooser).facts
                if inner is not None:
                    fields["chooser_value"] = chooser.facts
        return fields

    def configure(self, task: str | None, sets: list[str]):
        """(the TrainConfig-like config the episodes run, the overrides it makes of the run's
        own: config.overrides.config_changes rows) for `--task` (None: the run's own task; for a
        reference, the task to run, default the paper's 6D task) and `--set` items. A student
        takes them in its student diagram's teacher part, as a teacher's env does; a primitive
        run's executor and outcome settings are the policy's own, so `--set` reaches them too
        (e.g. primitive.success_at_rest=true), and its agent is re-aimed at the result."""
        from corn_drake.config.diagram_files import (load_teacher_config, primitive_run_on,
                                                     replace_task)
        from corn_drake.config.overrides import apply_sets, config_changes
        from corn_drake.config.training import TrainConfig

        if self.kind == "reference":
            from corn_drake.rl import scripted

            # A reference has no run: --task chooses its task, --set changes that task.
            base = TrainConfig(env=load_teacher_config(task))
            run_cfg = apply_sets(base, sets, only="env")
            self.agent = getattr(scripted, REFERENCES[self.run])(run_cfg.env.controller)
        elif self.kind == "planner":
            from corn_drake.config.diagram_files import load_primitive_env_config
            from corn_drake.config.planner import PlannerRunConfig
            from corn_drake.rl.planner.search import PlannerPolicy

            # env (--task, task.* ...), primitive.* and planner.* through the common path; the
            # default task is the paper's 6D task on the primitive policies' env layer.
            base = PlannerRunConfig(env=load_primitive_env_config(task or "full6d"))
            run_cfg = apply_sets(base, sets, only=("env", "primitive", "planner"))
            run_cfg.check()
            self.agent = PlannerPolicy(run_cfg.planner, run_cfg.primitive)
        elif self.kind == "primitive":
            base = self.config
            run_cfg = primitive_run_on(base, task, sets)
            self.agent.primitive_config = run_cfg.primitive
            # An outcome-model chooser predicts the evaluated task's reward and success.
            self.agent.task = run_cfg.env.task
        else:
            base = self.config if self.kind == "train" else TrainConfig(env=self.config.env.teacher)
            run_cfg = replace_task(base, task) if task is not None else base
            run_cfg = apply_sets(run_cfg, sets, only="env")
        return run_cfg, config_changes(base, run_cfg)

    def student_env(self, teacher_env, perception: str | None):
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


def weights_hash(run_dir: Path, checkpoint: Path) -> str:
    """sha256 over run folder `run_dir`'s config.yaml, its weights' `checkpoint` file and the
    chooser files beside them (CHOOSER_FILES)."""
    import hashlib

    from corn_drake.run_folders.config_file import run_config_path

    digest = hashlib.sha256()
    files = [run_config_path(run_dir), checkpoint,
             *(run_dir / name for name in CHOOSER_FILES if (run_dir / name).is_file())]
    for path in files:
        digest.update(Path(path).name.encode() + b"\0" + Path(path).read_bytes())
    return digest.hexdigest()


def run_kind_of(run: str, references: bool = True) -> str:
    """"reference" for a reference controller's name (with `references`), else the kind of run
    folder `run` is (run_folders.config_file.run_kind: an error naming --run for neither)."""
    from corn_drake.run_folders.config_file import run_kind

    if not references:  # `ship`: only a trained run has weights to pack
        return run_kind(run)
    if run in REFERENCES:
        return "reference"
    if run == PLANNER:
        return "planner"
    return run_kind(run, or_else=f"a reference ({', '.join(REFERENCES)})")


def load_any_run(run: str, checkpoint: str = "", references: bool = True) -> LoadedRun:
    """The run `run` of any kind, loaded as evaluate and ship both take it: its config, its
    agent with the weights of checkpoints/last.pt (prev.pt if need be) or, for a teacher or
    primitive run, the kept `checkpoint` file. Without `references` a reference controller's
    name is not a run (it is looked for as a run folder)."""
    from corn_drake.errors import InputError

    kind = run_kind_of(run, references)
    if checkpoint and kind not in ("train", "primitive"):
        raise InputError(f"--checkpoint {checkpoint} picks one of a teacher run's kept "
                         f"checkpoints; --run {run} is not a `corn-drake train` run")
    if kind in ("reference", "planner"):
        return LoadedRun(kind, run, None, None, run)
    if kind == "distill":
        from corn_drake.rl.checkpoints import load_student_run_with_step

        cfg, agent, steps = load_student_run_with_step(run)
        policy, folder = "student", Path(run)
    elif kind == "primitive":
        from corn_drake.rl.checkpoints import agent_weights_folder
        from corn_drake.rl.primitive.agent import load_primitive_run

        cfg, agent, steps = load_primitive_run(run, checkpoint)
        # A shipped outcome-model folder reads a sibling folder's actor and critic.
        policy, folder = cfg.policy, agent_weights_folder(run, cfg.agent_weights)
    else:
        from corn_drake.rl.checkpoints import load_run_with_step

        cfg, agent, steps = load_run_with_step(run, checkpoint)
        policy, folder = cfg.policy, Path(run)
    return LoadedRun(kind, run, cfg, agent, policy, steps, agent.checkpoint_file, folder)
