"""DAgger distillation of the student from a trained teacher, with truncated BPTT through its GRU.

One rollout serves both policies: StudentEnvs observe {"student", "teacher"} of the same state.
Each window of `cfg.window` steps of every env:

  * at every step the student runs on its observation (no gradients), the GRU state carried
    from step to step and zeroed where an episode starts; the teacher labels the same state
    from its privileged observation (its Gaussian: mean and state-independent log-std);
  * each env executes, with probability beta, the teacher's mean action, otherwise the
    student's own (its mean, or a sample with cfg.student_action: sample), clipped to [-1, 1].
    beta falls linearly from cfg.beta_start to 0 over cfg.beta_anneal_steps env steps: early
    episodes follow the teacher to states worth learning, later ones visit the states the
    student itself reaches (DAgger's point);
  * then one optimiser step on the mean per-step KL(teacher || student) over the window,
    recomputed with gradients from the GRU state at the window's start (detached: the
    gradient reaches the window's first step and no step before it).

The recomputation doubles the student's forward passes but keeps the loss a function of a
recorded window (window_loss), which is what the tests check on a fixed dataset. With the
student's parameters unchanged inside a window, it gives the rollout's outputs exactly.

Run folder as the teacher's (rl/training/ppo_trainer.py): config.yaml (a DistillConfig),
checkpoints/last.pt (atomic, prev.pt kept), tb/, metrics.json, plots/. A killed run resumes at its last checkpoint's
step with the same student, optimiser, RNG streams and beta; envs start fresh episodes (env
state is not checkpointed, as for the teacher), and the GRU state starts from zero with them.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from corn_drake.config.training import DistillConfig
from corn_drake.contract import STUDENT_OBS_KEYS
from corn_drake.errors import InputError, load_error_detail
from corn_drake.storage.checkpoint_files import load_checkpoint, save_checkpoint
from corn_drake.storage.atomic_files import write_json
from corn_drake.nn.student import StudentPolicy
from corn_drake.nn.threads import torch_threads
from corn_drake.rl.ppo.agent import TeacherAgent, obs_to_tensors
from corn_drake.rl.device import training_device
from corn_drake.rl.envs.vec_env import EnvBatch
from corn_drake.rl.run_progress import (count_episodes_per_object, progress_state, run_env_factory,
                                        recent_mean, restore_progress, to_cpu)
from corn_drake.contract import RECENT_EPISODES

CHECKPOINT_KEYS = ("kind", "student", "optimizer", "global_step", "update_index", "beta",
                   "history", "recent_episodes", "episodes_per_object", "torch_rng", "generator",
                   "np_rng")


def make_env_batch(env_config, seed: int, workers: int, envs_per_worker: int,
                   ray_address: str = "", start_episode: int = 0):
    """The run's envs: `envs_per_worker` envs in this process (workers == 0), or on `workers`
    Ray actors stepped in lock step (the DAgger student's; `env_config` a teacher or a student
    diagram config). The PPO trainer collects whole segments instead (rl/workers/segment_workers.py),
    the primitive trainer rounds of primitives (rl/workers/primitive_workers.py)."""
    factory = run_env_factory(env_config, seed, workers, envs_per_worker, start_episode)
    if workers > 0:
        from corn_drake.rl.workers.ray_workers import RayEnvBatch, init_ray

        init_ray(ray_address or None)
        return RayEnvBatch(factory, workers, envs_per_worker)
    return EnvBatch(factory, envs_per_worker)


def gaussian_kl(mean_p: torch.Tensor, log_std_p: torch.Tensor, mean_q: torch.Tensor,
                log_std_q: torch.Tensor) -> torch.Tensor:
    """KL(p || q) of diagonal Gaussians, summed over the last (action) axis; log-stds broadcast
    against the means (a state-independent (A,) log-std is fine)."""
    var_p, var_q = torch.exp(2 * log_std_p), torch.exp(2 * log_std_q)
    per_dim = log_std_q - log_std_p + (var_p + (mean_p - mean_q) ** 2) / (2 * var_q) - 0.5
    return per_dim.sum(-1)


def window_loss(student: StudentPolicy, obs: dict[str, torch.Tensor], starts: torch.Tensor,
                hidden: torch.Tensor, teacher_mean: torch.Tensor, teacher_log_std: torch.Tensor
                ) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean per-step KL(teacher || student) over one BPTT window, and the GRU state after it.

    obs: student keys (B, T, ...); starts (B, T) episode starts; hidden (layers, B, H) the state
    before the window (detached here, so no gradient flows into earlier windows); teacher_mean
    (B, T, A) and teacher_log_std (A,) the teacher's labels of the same steps."""
    kl, _, hidden_after = window_terms(student, obs, starts, hidden, teacher_mean, teacher_log_std)
    return kl, hidden_after


def window_terms(student: StudentPolicy, obs, starts, hidden, teacher_mean, teacher_log_std):
    """window_loss's KL, the RMS difference of the two policies' mean actions over the window
    (detached: what the executed actions differ by, logged beside the KL), and the GRU state."""
    out = student(obs, hidden.detach(), starts)
    kl = gaussian_kl(teacher_mean, teacher_log_std, out.mean, out.log_std)
    rms = (out.mean.detach() - teacher_mean).pow(2).mean().sqrt()
    return kl.mean(), rms, out.hidden


def student_tensors(obs: dict[str, np.ndarray], device) -> dict[str, torch.Tensor]:
    return {k: torch.as_tensor(np.asarray(obs[k]), dtype=torch.float32, device=device)
            for k in STUDENT_OBS_KEYS}


class DaggerTrainer:
    def __init__(self, cfg: DistillConfig, out: str | Path, student: StudentPolicy,
                 teacher: TeacherAgent):
        """`student` built on its encoder (nn/student_io.student_from_encoder), `teacher` a
        trained agent (rl/ppo/teacher_runs.load_run); reads the run's checkpoint if there is one."""
        cfg.check()
        self.cfg, self.out = cfg, Path(out)
        self.device = training_device(cfg.device)
        torch.manual_seed(cfg.seed)
        self.np_rng = np.random.default_rng(cfg.seed)
        self.generator = torch.Generator().manual_seed(cfg.seed)
        self.teacher = teacher.to(self.device).eval()
        for p in self.teacher.parameters():
            p.requires_grad_(False)
        # The student reads goal, joints and previous action standardised as the teacher reads
        # them (a checkpoint's buffers replace these on resume; they are the same values).
        student.set_token_statistics_from_context(teacher.context_normalizer.mean,
                                                  teacher.context_normalizer.var)
        # The student's state-independent log-std starts at the teacher's: from the default 0,
        # Adam moves it ~lr per update, and KL(teacher || student) stayed ~3.7 nats for thousands
        # of updates on the std gap alone (teacher log-std -0.5 over 20 actions), hiding the
        # mean's progress. A resumed run's checkpoint replaces it.
        with torch.no_grad():
            student.log_std.copy_(teacher.log_std.detach().to(student.log_std))
        self.student = student.to(self.device)
        self.optimizer = torch.optim.Adam([p for p in student.parameters() if p.requires_grad],
                                          lr=cfg.lr)
        self.global_step, self.update_index, self.history = 0, 0, []
        self.recent_episodes: list[dict] = []
        self.episodes_per_object: dict[str, int] = {}
        self.checkpoint_path = self.out / "checkpoints" / "last.pt"
        self._load()
        self.n_envs = max(cfg.workers, 1) * cfg.envs_per_worker
        start = sum(self.episodes_per_object.values()) // self.n_envs
        self.envs = make_env_batch(cfg.env, cfg.seed, cfg.workers, cfg.envs_per_worker,
                                   cfg.ray_address, start)

    @property
    def beta(self) -> float:
        return self.cfg.beta(self.global_step)

    # --- checkpoints -------------------------------------------------------------------------
    def _save(self) -> None:
        state = {"kind": "student", "student": to_cpu(self.student.state_dict()),
                 "optimizer": to_cpu(self.optimizer.state_dict()),
                 "beta": self.beta, **progress_state(self)}
        save_checkpoint(self.checkpoint_path, state)

    def _load(self) -> None:
        state = load_checkpoint(self.checkpoint_path, required=CHECKPOINT_KEYS)
        if state is None:
            return
        if state["kind"] != "student":
            raise InputError(f"{self.checkpoint_path} is not a student checkpoint")
        try:
            self.student.load_state_dict(state["student"])
        except RuntimeError as e:
            raise InputError(f"{self.checkpoint_path}: the saved student does not fit this "
                             f"version ({load_error_detail(e)})") from None
        self.optimizer.load_state_dict(state["optimizer"])
        restore_progress(self, state)

    # --- one window --------------------------------------------------------------------------
    def _collect(self, obs_np, hidden, starts):
        """`cfg.window` steps of every env; returns the window, the carried state and stats."""
        device, E = self.device, self.n_envs
        beta = self.beta
        window = {"obs": [], "starts": [], "teacher_mean": []}
        hidden0, episodes, sim_errors, teacher_steps = hidden, [], 0, 0
        self.student.eval()
        for _ in range(self.cfg.window):
            s_obs = student_tensors(obs_np["student"], device)
            # In-process envs run Open3D's ICP in this process: its spinning worker threads made
            # one student step take 140-330 ms with torch's 2 threads against 5 ms with 1.
            with torch.no_grad(), torch_threads(1 if self.cfg.workers == 0 else None):
                t_mean, _ = self.teacher(obs_to_tensors(obs_np["teacher"], device))
                out = self.student({k: v.unsqueeze(1) for k, v in s_obs.items()}, hidden,
                                   starts.unsqueeze(1))
            hidden, action = out.hidden, out.mean[:, 0]
            if self.cfg.student_action == "sample":
                noise = torch.randn(action.shape, generator=self.generator).to(device)
                action = action + out.log_std.exp() * noise
            use_teacher = (torch.rand(E, generator=self.generator) < beta).to(device)
            teacher_steps += int(use_teacher.sum())
            action = torch.where(use_teacher[:, None], t_mean, action).clamp(-1, 1)
            step = self.envs.step(action.cpu().numpy())
            for key, value in (("obs", s_obs), ("starts", starts), ("teacher_mean", t_mean)):
                window[key].append(value)
            starts = torch.as_tensor(step.terminated | step.truncated, device=device)
            episodes += step.episode_stats
            sim_errors += step.sim_errors
            obs_np = step.obs
        self.student.train()
        batch = {"obs": {k: torch.stack([o[k] for o in window["obs"]], dim=1)
                         for k in STUDENT_OBS_KEYS},
                 "starts": torch.stack(window["starts"], dim=1),
                 "teacher_mean": torch.stack(window["teacher_mean"], dim=1),
                 "hidden": hidden0}
        stats = {"episodes": episodes, "sim_errors": sim_errors,
                 "teacher_action_fraction": teacher_steps / (E * self.cfg.window)}
        return batch, obs_np, hidden, starts, stats

    def _update(self, batch) -> tuple[float, float]:
        """One optimiser step on the window's KL; (KL, RMS mean-action error) before the step."""
        loss, rms, _ = window_terms(self.student, batch["obs"], batch["starts"], batch["hidden"],
                                    batch["teacher_mean"], self.teacher.log_std.detach())
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.student.parameters(), self.cfg.max_grad_norm)
        self.optimizer.step()
        return float(loss.detach()), float(rms)

    def train(self, progress: bool = True) -> dict:
        from torch.utils.tensorboard import SummaryWriter
        from tqdm import tqdm

        self.out.mkdir(parents=True, exist_ok=True)
        writer = SummaryWriter(str(self.out / "tb"))
        cfg, E = self.cfg, self.n_envs
        obs_np = self.envs.reset()
        hidden = self.student.initial_state(E)
        starts = torch.ones(E, dtype=torch.bool, device=self.device)  # every env begins one
        bar = tqdm(total=cfg.total_steps, initial=self.global_step, disable=not progress,
                   desc="distill", unit="step")
        losses, action_errors, fractions = [], [], []
        sim_errors, episodes_since, t0 = 0, 0, time.perf_counter()
        steps_since = 0
        while self.global_step < cfg.total_steps:
            batch, obs_np, hidden, starts, stats = self._collect(obs_np, hidden, starts)
            loss, rms = self._update(batch)
            losses.append(loss)
            action_errors.append(rms)
            fractions.append(stats["teacher_action_fraction"])
            sim_errors += stats["sim_errors"]
            episodes_since += len(stats["episodes"])
            steps = cfg.window * E
            self.global_step += steps
            steps_since += steps
            self.update_index += 1
            self.recent_episodes = (self.recent_episodes + stats["episodes"])[-RECENT_EPISODES:]
            count_episodes_per_object(self.episodes_per_object, stats["episodes"])
            bar.update(steps)
            if self.update_index % cfg.log_every == 0 or self.global_step >= cfg.total_steps:
                row = self._log_row(losses, action_errors, fractions, episodes_since,
                                    sim_errors, steps_since / (time.perf_counter() - t0))
                self.history.append(row)
                for key, value in row.items():
                    if key not in ("step", "update"):
                        writer.add_scalar(f"distill/{key}", value, self.global_step)
                bar.set_postfix(loss=f"{row['loss']:.3f}", success=f"{row['success_rate']:.2f}",
                                beta=f"{row['beta']:.2f}")
                if not progress:
                    print(f"step {self.global_step}: loss {row['loss']:.4f} action rms "
                          f"{row['action_rms_error']:.3f} beta {row['beta']:.2f} "
                          f"success {row['success_rate']:.2f} "
                          f"{row['steps_per_s']:.0f} steps/s", flush=True)
                losses, action_errors, fractions, sim_errors, episodes_since = [], [], [], 0, 0
                steps_since, t0 = 0, time.perf_counter()
            if self.update_index % cfg.checkpoint_every == 0:
                self._save()
        self._save()
        writer.close()
        bar.close()
        metrics = {"policy": "student", "teacher": cfg.teacher, "global_step": self.global_step,
                   "updates": self.update_index, "beta": self.beta,
                   "perception": cfg.env.segmentation.mode,
                   "trainable": self.student.trainable_summary(),
                   "final": self.history[-1] if self.history else {},
                   "episodes_per_object": dict(sorted(self.episodes_per_object.items())),
                   "history": self.history}
        if hasattr(self.envs, "record"):  # Ray workers: where they ran, what died and why
            metrics.update(self.envs.record.report())
        write_json(self.out / "metrics.json", metrics)
        plot_distill_curves(self.history, self.out / "plots" / "learning_curve.png")
        return metrics

    def _log_row(self, losses, action_errors, fractions, episodes, sim_errors,
                 steps_per_s) -> dict:
        recent = self.recent_episodes
        return {"step": self.global_step, "update": self.update_index,
                "loss": float(np.mean(losses)),
                "action_rms_error": float(np.sqrt(np.mean(np.square(action_errors)))),
                "beta": self.beta,
                "teacher_action_fraction": float(np.mean(fractions)),
                "steps_per_s": steps_per_s, "episodes": episodes, "sim_errors": sim_errors,
                "success_rate": recent_mean(recent, "success"),
                "episode_length": recent_mean(recent, "length"),
                "tracking_translation_error_m": recent_mean(recent, "mean_translation_error_m"),
                "tracking_rotation_error_deg": recent_mean(recent, "mean_rotation_error_deg")}


def plot_distill_curves(history: list[dict], path: Path) -> None:
    """DAgger loss and success rate against env steps."""
    from matplotlib.figure import Figure

    from corn_drake.storage.atomic_files import atomic_path

    if not history:
        return
    steps = [h["step"] for h in history]
    fig = Figure(figsize=(9, 3.2))
    axes = fig.subplots(1, 2)
    axes[0].plot(steps, [h["loss"] for h in history], label="KL(teacher || student)")
    if all("action_rms_error" in h for h in history):
        axes[0].plot(steps, [h["action_rms_error"] for h in history],
                     label="RMS mean-action error")
    axes[0].set(xlabel="env steps", yscale="log")
    axes[0].legend()
    axes[1].plot(steps, [h["success_rate"] for h in history], label="success")
    axes[1].plot(steps, [h["beta"] for h in history], "--", label="beta")
    axes[1].set(xlabel="env steps", ylabel=f"last {RECENT_EPISODES} episodes", ylim=(0, 1))
    axes[1].legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
