"""The configs a training run records in RUN/config.yaml: PPO (`corn-drake train`, TrainConfig) and
DAgger (`corn-drake distill`, DistillConfig), both on the run settings they share (RunSettings).

No `from __future__ import annotations`: yaml_load_typed needs real types on the fields.
"""

import dataclasses as dc
import typing

from corn_drake.config.plumbing.bounds import check_bounds, one_of, relation, subset_of
from corn_drake.config.choices import (POLICY_KINDS, PRIMITIVE_POLICY, STUDENT_ACTIONS,
                                       STUDENT_PARAMETER_GROUPS)
from corn_drake.config.student import StudentDiagramConfig
from corn_drake.config.teacher import TeacherDiagramConfig
from corn_drake.errors import InputError


@dc.dataclass
class PPOConfig:
    """PPO settings; where each default comes from (paper = Table "Hyperparameters for PPO" of
    the CORN paper, code = the authors' models/rl/v6/ppo.py with cloud_arm_mlp_base.yaml, see
    shared/reference/corn_official_code.md section 4):

    gamma 0.99, gae_lambda 0.95, clip 0.3, epochs 8, lr 3e-4, kl_target 0.016: paper and code.
    kl_stop_factor 1.5: the paper's early-stopping KL target 0.024 = 1.5 x 0.016 (code: the
    same, the first minibatch of an update exempt). lr_min 1e-6, lr_max 1e-2 and the x1.5 / /1.5
    steps of the adaptive lr: code. minibatches 1: code (chunk_size 1, the whole rollout).
    policy_coef 0.5, value_coef 2.0: code (k_pi 0.5, k_val 2.0, and its value loss is
    0.5 * MSE, as ours). The paper's table prints "policy 2, value 0.5": the code's numbers
    with the names swapped; we follow the code, which produced the paper's results.
    bound_coef 0.02: paper and code; bound_limit 1.1 and max_grad_norm 1.0: code.
    Entropy bonus 0 (paper and code): none is implemented.

    separate_critic, critic_lr: ours, on by default, as every shipped PPO run (push_corn,
    push_state) was trained (the authors share the trunk: false). With it the value comes from
    a second head of the same shape on the same (detached) encoder features, trained by its own
    Adam at the fixed critic_lr on every minibatch of every epoch, whatever the policy's KL
    does, with its gradient clipped on its own. Why: at our 1-2k-transition batches the KL rule
    holds the shared lr near 1e-5 and stops updates after 1-4 steps, so a shared critic never
    fits the returns (the results page, the one-step PPO probe).
    """
    # Range checks (config/plumbing/bounds.py): what check_bounds refuses.
    BOUNDS = {"gamma": "(0, 1]",
              "gae_lambda": "[0, 1]", "clip": "> 0", "epochs": ">= 1", "minibatches": ">= 1",
              "lr": "> 0", "lr_min": "> 0", "lr_max": "> 0", "kl_target": "> 0",
              "kl_stop_factor": "> 0", "policy_coef": ">= 0", "value_coef": ">= 0",
              "bound_coef": ">= 0", "bound_limit": "> 0", "max_grad_norm": "> 0",
              "critic_lr": "> 0"}
    # The adaptive lr moves within [lr_min, lr_max] from lr (rl/ppo): an lr outside it would be
    # clamped at the first update, or train there (lr_min=1 trained at lr 1.0).
    RELATIONS = (relation("lr_min", "<= {lr}", lambda low, lr: low <= lr, "lr"),
                 relation("lr", "<= {lr_max}", lambda lr, high: lr <= high, "lr_max"))

    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip: float = 0.3
    epochs: int = 8
    minibatches: int = 1
    lr: float = 3e-4
    lr_min: float = 1e-6
    lr_max: float = 1e-2
    kl_target: float = 0.016
    kl_stop_factor: float = 1.5
    policy_coef: float = 0.5
    value_coef: float = 2.0  # x 0.5 * (V - R)^2 in PPO.losses, as the authors' k_val
    bound_coef: float = 0.02
    bound_limit: float = 1.1
    max_grad_norm: float = 1.0
    separate_critic: bool = True
    critic_lr: float = 3e-4


@dc.dataclass
class RunSettings:
    """What every training run (train, distill) records about how it runs, whatever it learns:
    its length, where its envs run, its seed, how often it checkpoints, its pretrained encoder
    and the learner's device. TrainConfig and DistillConfig inherit these fields, so their
    YAML keys stay flat (a run's config.yaml reads as before) and the two commands share one
    set of flags (arguments/run_flags.py) and bounds."""
    # Range checks (config/plumbing/bounds.py): what check_bounds refuses.
    BOUNDS = {
              # envs_per_worker: each env is a Drake diagram of ~60 MB; 100000 hung for minutes
              # building them before failing.
              "total_steps": ">= 1", "workers": ">= 0", "envs_per_worker": "[1, 256]",
              "seed": "seed",
              "checkpoint_every": ">= 1",
              # Free text: Ray and the encoder loader say what is wrong with them, with their
              # flag (--ray-address, --encoder), before anything is written.
              "ray_address": "text", "encoder": "text",
              # Its syntax; rl/device.training_device checks this machine has it.
              "device": "device"}
    # A cluster runs only Ray workers: an address with no worker to send was accepted and the
    # run stayed on this machine without a word (issue 63).
    RELATIONS = (relation("ray_address", "empty when {workers} is 0 (--ray-address needs "
                          "--workers N: with none the envs run in this process)",
                          lambda address, workers: not address or workers > 0, "workers"),)
    total_steps: int = 20_000  # environment steps (transitions) over all envs
    workers: int = 0  # 0: envs in this process; > 0: Ray actors
    envs_per_worker: int = 4
    seed: int = 0
    checkpoint_every: int = 5  # updates (train) or optimiser steps (distill) between checkpoints
    ray_address: str = ""  # a Ray cluster's address; empty: a local Ray
    # The pretrained encoder checkpoint the policy uses (train: frozen, for corn / pn / p2v-lite
    # / rot; distill: the student's patch encoder starts from it).
    encoder: str = ""
    # Accept an encoder whose recorded pretraining metric is below its bar (the demo's tiny
    # pretraining, smoke tests); recorded so evaluate accepts the run too.
    allow_weak_encoder: bool = False
    # Torch device of the learner (agent, batched inference, updates): "cpu", "cuda" or
    # "cuda:N". Envs, observations and actions stay numpy on the CPU either way, and
    # checkpoints hold CPU tensors, so a run may resume on another device.
    device: str = "cpu"


@dc.dataclass
class TrainConfig(RunSettings):
    # Range checks (config/plumbing/bounds.py): what check_bounds refuses.
    # Sizes that allocate memory have upper bounds (issue 63: 1e9 ran into a MemoryError
    # traceback after the config was written): 4096 steps of 256 envs' clouds is ~6 GB of rollout.
    BOUNDS = {
              "rollout_steps": "[1, 4096]", "snapshot_every": ">= 0", "init_log_std": "[-20, 5]",
              # A PPO run's policy: a teacher variant, or the primitive policy (whose runs load
              # as PrimitiveTrainConfig; `train` sends them there by this field).
              "policy": one_of((*POLICY_KINDS, PRIMITIVE_POLICY)),
              "init_from": "text"}  # a run folder: checked by rl/checkpoints.check_init_source
    # A rollout is rollout_steps x envs transitions (envs: envs_per_worker on each of
    # max(workers, 1)); more minibatches than transitions were cut to one each without a word
    # (torch.chunk), so the optimiser steps the user asked for did not happen (issue 63).
    RELATIONS = (relation("ppo.minibatches", "<= the rollout's transitions, {rollout_steps} x "
                          "{envs_per_worker} x max(1, {workers})",
                          lambda m, steps, envs, workers: m <= steps * envs * max(1, workers),
                          "rollout_steps", "envs_per_worker", "workers"),)
    policy: str = "state"
    rollout_steps: int = 32  # per env and update
    # Keep a copy of the checkpoint as checkpoints/step_NNNNNNNNN.pt each time training passes
    # a multiple of this many env steps (0: none). last.pt is overwritten; the copies let a
    # comparison evaluate every run at the same wall-clock (`evaluate --checkpoint`).
    snapshot_every: int = 0
    # A finished run whose trained agent (weights, log-std, observation normalisers) this run
    # starts from, with a fresh optimiser, reward scaler and step count: a curriculum, e.g. the
    # push teacher carried on to push_turn. Same policy, encoder and network shape; the
    # source's log-std replaces init_log_std. Its env steps are not counted in this run's.
    init_from: str = ""
    # Initial log-std of the Gaussian policy: 0 as in the paper; the reduced benchmark starts
    # lower, since at std 1 every step jitters the hand by most of max_position_delta and a
    # run of a few 100k steps cannot shrink it (Adam moves it ~lr per optimiser step).
    init_log_std: float = 0.0
    ppo: PPOConfig = dc.field(default_factory=PPOConfig)
    env: TeacherDiagramConfig = dc.field(default_factory=TeacherDiagramConfig)

    def check(self) -> None:
        """InputError naming the first field a run cannot start with (the env's too)."""
        check_bounds(self)
        self.env.check()


@dc.dataclass
class DistillConfig(RunSettings):
    # Range checks (config/plumbing/bounds.py): what check_bounds refuses.
    # Sizes that allocate memory have upper bounds (issue 63: 1e9 ran into a MemoryError
    # traceback after the config was written): a BPTT window of 1024 steps keeps every step's activations.
    BOUNDS = {"window": "[1, 1024]",
              "beta_start": "[0, 1]", "beta_anneal_steps": ">= 0", "lr": "> 0",
              "max_grad_norm": "> 0", "log_every": ">= 1",
              "teacher": "text",  # a run folder: rl/training/dagger loads and checks it
              "frozen": subset_of(STUDENT_PARAMETER_GROUPS),
              "student_action": one_of(STUDENT_ACTIONS)}
    teacher: str = ""  # the teacher's run folder (`corn-drake train --out`)
    # Student parameter groups kept at their initial values (nn/student.PARAMETER_GROUPS).
    frozen: typing.List[str] = dc.field(default_factory=list)
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
    checkpoint_every: int = 50  # optimiser steps (windows)
    log_every: int = 10  # windows per metrics row / TensorBoard point
    env: StudentDiagramConfig = dc.field(default_factory=StudentDiagramConfig)

    def check(self) -> None:
        """InputError naming the first field a run cannot start with."""
        check_bounds(self)
        if self.student_action not in STUDENT_ACTIONS:
            raise InputError(f"student_action must be one of {', '.join(STUDENT_ACTIONS)}, got "
                             f"{self.student_action!r}")
        self.env.check()

    def beta(self, step: int) -> float:
        """The teacher-action probability at env step `step`."""
        if self.beta_anneal_steps == 0:
            return 0.0
        return self.beta_start * max(0.0, 1.0 - step / self.beta_anneal_steps)
