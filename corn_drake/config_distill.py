"""DistillConfig: one DAgger run of the student (`corn-drake distill`), recorded in RUN/config.yaml.

No `from __future__ import annotations`: yaml_load_typed needs real types on the fields.
"""

import dataclasses as dc
import typing

from corn_drake.config_student import StudentDiagramConfig
from corn_drake.errors import InputError

STUDENT_ACTIONS = ("mean", "sample")


@dc.dataclass
class DistillConfig:
    teacher: str = ""  # the teacher's run folder (`corn-drake train --out`)
    # The contact-pretrained CORN encoder the student's patch encoder starts from (default: the
    # one the teacher run records).
    encoder: str = ""
    allow_weak_encoder: bool = False
    # Student parameter groups kept at their initial values (nn/student.PARAMETER_GROUPS).
    frozen: typing.List[str] = dc.field(default_factory=list)
    total_steps: int = 20_000  # environment steps over all envs
    workers: int = 0  # 0: envs in this process; > 0: Ray actors
    envs_per_worker: int = 4
    # Truncated BPTT: one optimiser step per window of this many steps of every env; the GRU
    # state is carried (detached) from one window into the next.
    window: int = 8
    # Probability that an env executes the teacher's action instead of the student's at a
    # step: beta_start at step 0, linearly down to 0 at beta_anneal_steps (0: never).
    beta_start: float = 1.0
    beta_anneal_steps: int = 10_000
    # The student's own action when it acts: its Gaussian mean, or a sample of it.
    student_action: str = "mean"
    lr: float = 3e-4
    max_grad_norm: float = 1.0
    seed: int = 0
    checkpoint_every: int = 50  # optimiser steps (windows)
    log_every: int = 10  # windows per metrics row / TensorBoard point
    ray_address: str = ""
    device: str = "cpu"
    env: StudentDiagramConfig = dc.field(default_factory=StudentDiagramConfig)

    def check(self) -> None:
        """InputError naming the first field a run cannot start with."""
        for name in ("total_steps", "envs_per_worker", "window", "checkpoint_every", "log_every"):
            if getattr(self, name) < 1:
                raise InputError(f"{name} must be >= 1, got {getattr(self, name)}")
        for name in ("workers", "beta_anneal_steps"):
            if getattr(self, name) < 0:
                raise InputError(f"{name} must be >= 0, got {getattr(self, name)}")
        if not 0.0 <= self.beta_start <= 1.0:
            raise InputError(f"beta_start must be in [0, 1] (a probability), got {self.beta_start}")
        if self.student_action not in STUDENT_ACTIONS:
            raise InputError(f"student_action must be one of {', '.join(STUDENT_ACTIONS)}, got "
                             f"{self.student_action!r}")
        if not (self.lr > 0 and self.max_grad_norm > 0):
            raise InputError(f"lr and max_grad_norm must be > 0, got {self.lr}, {self.max_grad_norm}")
        self.env.check()

    def beta(self, step: int) -> float:
        """The teacher-action probability at env step `step`."""
        if self.beta_anneal_steps == 0:
            return 0.0
        return self.beta_start * max(0.0, 1.0 - step / self.beta_anneal_steps)
