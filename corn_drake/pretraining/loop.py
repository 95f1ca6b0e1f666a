"""The training loop every encoder pretraining shares: contact (pretraining/contact.py) and the
pretext baselines P2V-lite and ROT (pretraining/pretext.py).

A subclass says what a step's loss is, what an evaluation measures and which module is the
encoder; this loop owns the rest, so every pretraining has the same run folder: config.yaml
(written by the command), checkpoints/last.pt (atomic, resumable to the same step with every RNG
stream; the one before kept as prev.pt and used if last.pt is unreadable), tb/, metrics.json and
encoder.pt (the frozen-encoder export with its pretraining record). AdamW with a linear warm-up
and a cosine decay to min_lr, gradient clipping at max_grad_norm.

The config is read by field name (model, steps, batch_size, lr, min_lr, weight_decay,
warmup_steps, max_grad_norm, eval_every, checkpoint_every, seed): PretrainConfig and
PretextConfig both have them.
"""

from __future__ import annotations

import math
import random
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

from corn_drake.errors import InputError, network_mismatch
from corn_drake.storage.checkpoint_files import load_checkpoint, save_checkpoint
from corn_drake.storage.atomic_files import write_json
from corn_drake.nn.encoders.encoder_files import NormalizedEncoder, save_encoder
from corn_drake.nn.encoders.input_normalization import InputNormalization


def global_rng_state() -> dict:
    """Every global RNG a training step may draw from (dropout uses torch's), so a resumed run
    continues the same random stream as an uninterrupted one."""
    state = {"torch": torch.get_rng_state(), "numpy": np.random.get_state(),
             "python": random.getstate()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_global_rng_state(state: dict) -> None:
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    random.setstate(state["python"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


class PretrainLoop:
    """Subclasses define build_model, batch_loss, evaluate and final_metrics (and may override
    setup, after_optimizer_step, write_plots, encoder_kind); `self.model.encoder` is exported.
    """

    # Evaluate the held-out split once before the first step, as the history's step-0 row: the
    # untrained model's loss, which a pretext task's record is read against.
    evaluate_untrained = False

    def __init__(self, cfg, out: str | Path):
        self.cfg, self.out = cfg, Path(out)
        torch.manual_seed(cfg.seed)  # the model's initial weights are the seed's
        self.model = self.build_model()
        # Exported with the encoder: policies normalise their inputs the same way.
        self.normalization = InputNormalization()
        self.optimizer = torch.optim.AdamW([p for p in self.model.parameters() if p.requires_grad],
                                           lr=cfg.lr, weight_decay=cfg.weight_decay)
        self.generator = torch.Generator().manual_seed(cfg.seed)
        self.step, self.history, self.initial_loss = 0, [], None
        self.train_seconds = 0.0  # optimisation wall-clock over all runs (resumes add to it)
        self.setup()
        self.checkpoint = self.out / "checkpoints" / "last.pt"
        self._load()  # resumes from last.pt (or prev.pt beside it) when there is one

    # --- what a subclass defines -----------------------------------------------------------
    def build_model(self) -> nn.Module:
        raise NotImplementedError

    def setup(self) -> None:
        """Loads the data (called after the model and optimiser exist, before a resume)."""

    def batch_loss(self) -> torch.Tensor:
        """The loss of one training batch, drawn with self.generator."""
        raise NotImplementedError

    def after_optimizer_step(self) -> None:
        """Called after every optimiser step, self.step not yet incremented (an EMA teacher)."""

    def evaluate(self, split: str) -> dict:
        """Metrics on a held-out split ({} when the data has none)."""
        raise NotImplementedError

    def final_metrics(self) -> dict:
        """What metrics.json and the encoder's pretraining record hold beyond the common keys."""
        raise NotImplementedError

    def write_plots(self) -> None:
        """Figures under out/plots/ (optional)."""

    @property
    def contact_head(self) -> nn.Module | None:
        """The head encoder.pt keeps beside the encoder (nn/encoder_io.load_contact_model):
        the contact models' (pretraining/contact.py); none for the pretext tasks."""
        return None

    @property
    def encoder_kind(self) -> str:
        """encoder.pt's kind (nn/encoder_io.ENCODER_KINDS)."""
        return self.cfg.model

    # --- the shared loop -------------------------------------------------------------------
    def lr_at(self, step: int) -> float:
        c = self.cfg
        if step < c.warmup_steps:
            return c.lr * (step + 1) / c.warmup_steps
        t = (step - c.warmup_steps) / max(c.steps - c.warmup_steps, 1)
        return c.min_lr + 0.5 * (c.lr - c.min_lr) * (1 + math.cos(math.pi * min(t, 1.0)))

    def _save(self):
        state = {"model": self.model.state_dict(), "optimizer": self.optimizer.state_dict(),
                 "generator": self.generator.get_state(), "rng": global_rng_state(),
                 "step": self.step, "history": self.history, "model_kind": self.cfg.model,
                 "train_seconds": self.train_seconds}
        save_checkpoint(self.checkpoint, state)

    def _load(self):
        state = load_checkpoint(self.checkpoint, required=("model", "optimizer", "generator",
                                                           "step", "history"))
        if state is None:
            return
        kind = state.get("model_kind", self.cfg.model)
        if kind != self.cfg.model:
            raise InputError(f"{self.checkpoint} holds a {kind!r} model, not {self.cfg.model!r}")
        try:
            self.model.load_state_dict(state["model"])
        except RuntimeError as e:  # a network changed since (e.g. the PointNet's input channels)
            raise network_mismatch(self.checkpoint, kind, e) from None
        self.optimizer.load_state_dict(state["optimizer"])
        self.generator.set_state(state["generator"])
        if "rng" in state:  # absent in checkpoints written before it was kept
            set_global_rng_state(state["rng"])
        self.step, self.history = state["step"], state["history"]
        self.train_seconds = state.get("train_seconds", 0.0)

    def _evaluation_row(self, loss: float | None) -> dict:
        row = {"step": self.step, "loss": loss,
               **{f"val_{k}": v for k, v in self.evaluate("val").items()}}
        self.history.append(row)
        return row

    def optimize(self, loss: torch.Tensor) -> None:
        """One optimiser step on `loss` at the schedule's learning rate; advances self.step."""
        for group in self.optimizer.param_groups:
            group["lr"] = self.lr_at(self.step)
        self.optimizer.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(self.model.parameters(), self.cfg.max_grad_norm)
        self.optimizer.step()
        self.after_optimizer_step()
        self.step += 1

    def train(self, progress: bool = True) -> dict:
        from torch.utils.tensorboard import SummaryWriter
        from tqdm import tqdm

        cfg = self.cfg
        writer = SummaryWriter(str(self.out / "tb"))
        bar = tqdm(total=cfg.steps, initial=self.step, disable=not progress, desc=f"pretrain {cfg.model}")
        t0 = time.perf_counter()
        if self.evaluate_untrained and self.step == 0 and not self.history:
            self._evaluation_row(None)
        while self.step < cfg.steps:
            t_step = time.perf_counter()
            loss = self.batch_loss()
            if self.initial_loss is None:
                self.initial_loss = loss.item()
            self.optimize(loss)
            self.train_seconds += time.perf_counter() - t_step
            writer.add_scalar("train/loss", loss.item(), self.step)
            writer.add_scalar("train/lr", self.lr_at(self.step - 1), self.step)
            bar.update(1)
            bar.set_postfix(loss=f"{loss.item():.3f}")
            if self.step % cfg.eval_every == 0 or self.step == cfg.steps:
                row = self._evaluation_row(loss.item())
                for k, v in row.items():
                    if k.startswith("val_"):
                        writer.add_scalar(f"val/{k[4:]}", v, self.step)
            if self.step % cfg.checkpoint_every == 0:
                self._save()
        bar.close()
        self._save()
        writer.close()
        metrics = {"model": cfg.model, "steps": self.step, "batch_size": cfg.batch_size,
                   "samples_seen": self.step * cfg.batch_size,
                   "seconds_this_run": time.perf_counter() - t0,
                   "train_seconds": self.train_seconds, "lr": cfg.lr,
                   "parameters": sum(p.numel() for p in self.model.parameters() if p.requires_grad),
                   **self.final_metrics()}
        write_json(self.out / "metrics.json", metrics)
        save_encoder(self.out / "encoder.pt",
                     NormalizedEncoder(self.encoder_kind, self.model.encoder, self.normalization),
                     pretraining=metrics, contact_head=self.contact_head)
        self.write_plots()
        return metrics
