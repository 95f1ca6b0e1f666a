"""Configs of the pretraining runs: contact pretraining (PretrainConfig) and the pretext baselines
(PretextConfig, `corn-drake pretrain --model p2v-lite|rot`), each recorded in RUN/config.yaml.

The optimisation fields have the same names in both (the loop in pretraining/loop.py reads
either); the pretext defaults differ by model (PRETEXT_DEFAULTS), so `pretext_config(model)` is
how a pretext config is made. No `from __future__ import annotations`: yaml_load_typed needs
real types on the fields.
"""

import dataclasses as dc

from corn_drake.config.plumbing.bounds import check_bounds, one_of, relation
from corn_drake.errors import InputError

# The contact-pretrained encoders (`pretrain --model corn|pointnet`).
CONTACT_MODELS = ("corn", "pointnet")
# The learning rate anneals from lr down to min_lr after a warm-up that must end within the run
# (pretraining/loop.py): both optimisation configs declare these.
_SCHEDULE = (relation("min_lr", "<= {lr}", lambda low, lr: low <= lr, "lr"),
             relation("warmup_steps", "<= {steps}", lambda w, steps: w <= steps, "steps"))


@dc.dataclass
class PretrainConfig:
    """Contact pretraining (paper: AdamW 2e-4, wd 5e-4, batch 1024, cosine schedule + warm-up)."""
    # Range checks (config/plumbing/bounds.py): what check_bounds refuses.
    # Sizes that allocate memory have upper bounds (issue 63: 1e9 ran into a MemoryError
    # traceback after the config was written): a batch 16x the paper's 1024; a million held-out samples.
    BOUNDS = {"steps": ">= 1",
              "batch_size": "[1, 16384]", "lr": "> 0", "min_lr": ">= 0", "weight_decay": ">= 0",
              "warmup_steps": ">= 0", "max_grad_norm": "> 0", "translate_std": ">= 0",
              "point_noise_std": ">= 0", "eval_every": ">= 1", "checkpoint_every": ">= 1",
              "eval_samples": "[1, 1000000]", "seed": "seed", "model": one_of(CONTACT_MODELS)}
    RELATIONS = _SCHEDULE
    model: str = "corn"  # corn | pointnet
    steps: int = 2000
    batch_size: int = 1024
    lr: float = 2e-4
    min_lr: float = 1e-6
    weight_decay: float = 5e-4
    warmup_steps: int = 100
    max_grad_norm: float = 4.0
    # Augmentation (train split only): yaw about the cloud centroid, translation, point noise.
    translate_std: float = 0.04  # m (0.1 in normalised units)
    point_noise_std: float = 0.004  # m (0.01 in normalised units)
    eval_every: int = 250
    checkpoint_every: int = 250
    eval_samples: int = 4096
    seed: int = 0

    def check(self) -> None:
        """InputError naming the first field no run can use (before anything is written)."""
        check_bounds(self)


PRETEXT_MODELS = ("p2v-lite", "rot")
TARGET_NORMS = ("instance", "layer")


@dc.dataclass
class PretextConfig:
    # Range checks (config/plumbing/bounds.py): what check_bounds refuses.
    # Sizes that allocate memory have upper bounds (issue 63: 1e9 ran into a MemoryError
    # traceback after the config was written): a batch 16x the contact pretraining's 1024; a million held-out samples.
    BOUNDS = {"steps": ">= 1",
              "batch_size": "[1, 16384]", "lr": "> 0", "min_lr": ">= 0", "weight_decay": ">= 0",
              "warmup_steps": ">= 0", "max_grad_norm": "> 0", "dropout": "[0, 1)",
              "point_noise_std": ">= 0", "mask_ratio": "(0, 1)", "smooth_l1_beta": "> 0",
              "ema_start_horizon": "> 0", "ema_end_horizon": "> 0", "ema_ramp_fraction": "(0, 1]",
              "eval_every": ">= 1", "checkpoint_every": ">= 1", "eval_samples": "[1, 1000000]",
              "seed": "seed", "model": one_of(PRETEXT_MODELS),
              "target_norm": one_of(TARGET_NORMS)}
    # The EMA teacher's decay rises over the ramp (see below): its horizon must not shrink.
    RELATIONS = (*_SCHEDULE, relation("ema_start_horizon", "<= {ema_end_horizon}",
                                      lambda start, end: start <= end, "ema_end_horizon"))
    model: str = "p2v-lite"  # p2v-lite | rot
    steps: int = 2000
    batch_size: int = 512  # point2vec's
    lr: float = 1e-3
    min_lr: float = 1e-6
    weight_decay: float = 0.05
    warmup_steps: int = 200
    max_grad_norm: float = 4.0
    # Dropout in the encoder's layers while pretraining: the paper's P2V-lite replaces
    # point2vec's DropPath (rate rising 0 -> 0.25 over 12 layers, 0.125 on average) by dropout
    # because the encoder has 2 layers; 0.1 is near that average.
    dropout: float = 0.1
    # Gaussian noise on every sampled point (m), as contact pretraining's 4 mm.
    point_noise_std: float = 0.004
    # --- P2V-lite -------------------------------------------------------------------------
    # point2vec's masking ratio: 10 of the 16 patches are masked.
    mask_ratio: float = 0.65
    # point2vec's loss: SmoothL1 with beta 2 on the layer-normalised teacher features.
    smooth_l1_beta: float = 2.0
    # How the teacher's final-layer features are normalised into targets: "layer" (point2vec's
    # default: over each patch's channels) or "instance" (over each channel's patches of one
    # cloud; data2vec's choice where layer-normalised targets collapsed). See pretext/p2v.py.
    target_norm: str = "instance"
    # EMA teacher: the decay rises linearly from 1 - 1/(ema_start_horizon * steps) to
    # 1 - 1/(ema_end_horizon * steps) over the first ema_ramp_fraction of the run, then stays.
    # point2vec: 0.9998 -> 0.99999 over the first 200 of 800 epochs (65.6k steps), i.e. a
    # teacher time constant of 5k -> 100k steps = 7.6 % -> 152 % of its run. Kept as fractions
    # of the run: point2vec's decays at its length would leave the teacher at its random
    # initialisation for a few-thousand-step run on a small library.
    ema_start_horizon: float = 0.076
    ema_end_horizon: float = 1.52
    ema_ramp_fraction: float = 0.25
    eval_every: int = 250
    checkpoint_every: int = 250
    eval_samples: int = 1024
    seed: int = 0

    def check(self) -> None:
        """InputError naming the first field no run can use."""
        check_bounds(self)  # every number's range, from BOUNDS above
        if self.model not in PRETEXT_MODELS:
            raise InputError(f"pretext model must be one of {PRETEXT_MODELS}, got {self.model!r}")
        if self.target_norm not in ("instance", "layer"):
            raise InputError(f"target_norm must be instance or layer, got {self.target_norm!r}")


# Per-model optimisation defaults. P2V-lite: point2vec's AdamW lr 1e-3, weight decay 0.05,
# warm-up over the first 10 % (80 of 800 epochs), cosine to 1e-6. ROT: the appendix gives no
# optimiser; CORN's contact pretraining's AdamW 2e-4 / 5e-4 is used, so the two patch-encoder
# pretrainings differ in their task, not their optimiser.
PRETEXT_DEFAULTS = {
    "p2v-lite": {"lr": 1e-3, "weight_decay": 0.05},
    "rot": {"lr": 2e-4, "weight_decay": 5e-4},
}


def pretext_config(model: str, steps: int = 2000, **fields) -> PretextConfig:
    """A checked PretextConfig for `model` with its defaults, a 10 % warm-up, and `fields`."""
    if model not in PRETEXT_MODELS:
        raise InputError(f"pretext model must be one of {PRETEXT_MODELS}, got {model!r}")
    values = {"warmup_steps": max(1, steps // 10), **PRETEXT_DEFAULTS[model], **fields}
    cfg = PretextConfig(model=model, steps=steps, **values)
    cfg.check()
    return cfg
