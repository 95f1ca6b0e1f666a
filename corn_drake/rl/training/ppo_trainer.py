"""PPO training of the teacher: rollouts (in-process or Ray workers), updates, logs, checkpoints.

Run folder layout: config.yaml, checkpoints/last.pt (atomic; the one before it kept as prev.pt),
tb/ (TensorBoard), metrics.json, plots/learning_curve.png. A killed run resumes from
checkpoints/last.pt (prev.pt if last.pt is unreadable) at the same update with the same
optimizer, normalisers and RNG state (environments start fresh episodes, continuing the rounds
over the library's train objects). metrics.json's episodes_per_object counts the finished
training episodes of each object over the whole run.

Each update's rollout is one segment (rl/ppo/segments.py): the learner draws the unit action noise
for every env and step, and the envs are stepped for the whole rollout where they are — in this
process by the learner's agent (`workers` 0), or inside Ray workers, each with a CPU copy of the
agent whose weights the learner broadcasts once per update (rl/workers/segment_workers.py). Both paths
act with the same noise, so they run the same episodes for the same seed.

`cfg.device` holds the agent, the in-process path's batched inference, the rollout tensors and
the PPO update; the envs step numpy arrays on the CPU, and the reward scaler and random
generators stay there too (the same random streams on any device). Checkpoints hold CPU tensors
only.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import torch

from corn_drake.config.training import TrainConfig
from corn_drake.errors import InputError
from corn_drake.storage.checkpoint_files import load_checkpoint, save_checkpoint
from corn_drake.storage.atomic_files import write_json
from corn_drake.rl.ppo.agent import TeacherAgent, obs_to_tensors
from corn_drake.rl.checkpoints import init_agent_state, snapshot_path
from corn_drake.rl.device import training_device
from corn_drake.rl.normalization import RewardScaler
from corn_drake.rl.ppo.ppo import PPO, compute_gae
from corn_drake.rl.ppo.segments import SegmentCollector
from corn_drake.contract import RECENT_EPISODES
from corn_drake.viz.learning_curves import plot_learning_curves
# to_cpu and count_episodes_per_object stay importable from here for existing callers.
from corn_drake.rl.run_progress import (count_episodes_per_object, progress_state,
                                        restore_progress, run_env_factory, to_cpu)

# What _load reads unconditionally: a checkpoint without one of these cannot resume the run.
CHECKPOINT_KEYS = ("policy", "agent", "ppo", "reward_scaler", "global_step", "update_index",
                   "history", "torch_rng", "generator", "np_rng")


@dataclasses.dataclass
class Rollout:
    """One update's rollout on the learner's device: flat observations (T * N, ..., with a frozen
    encoder's cached `features`), (T, N) tensors (actions (T, N, A), logp, values, scaled rewards,
    terminated, truncated, final_values), the bootstrap values (N,), and the collection's
    episodes and simulation errors."""
    obs: dict[str, torch.Tensor]
    stack: dict[str, torch.Tensor]
    last_values: torch.Tensor
    episodes: list[dict]
    sim_errors: int


def steps_trained(total: int, done: int, per_rollout: int) -> int:
    """The env steps a run asked for `total` ends at, from `done`: it trains whole rollouts of
    `per_rollout` steps until it has at least `total`."""
    if done >= total:
        return done
    return done + -(-(total - done) // per_rollout) * per_rollout


class Trainer:
    def __init__(self, cfg: TrainConfig, out: str | Path, encoder: torch.nn.Module | None = None):
        self.cfg, self.out = cfg, Path(out)
        self.device = training_device(cfg.device)  # a device this machine lacks: InputError
        torch.manual_seed(cfg.seed)
        self.np_rng = np.random.default_rng(cfg.seed)
        self.generator = torch.Generator().manual_seed(cfg.seed)
        self.agent = TeacherAgent(cfg.policy, encoder, separate_critic=cfg.ppo.separate_critic)
        with torch.no_grad():
            self.agent.log_std.fill_(cfg.init_log_std)
        self.agent.to(self.device)  # before the optimiser takes its parameters
        self.ppo = PPO(self.agent, cfg.ppo)
        n_envs = max(cfg.workers, 1) * cfg.envs_per_worker
        self.reward_scaler = RewardScaler(n_envs, cfg.ppo.gamma)
        self.global_step, self.update_index, self.history = 0, 0, []
        # The last 100 finished episodes behind the logged success rate and return; kept in the
        # checkpoint so a resumed run's curves continue instead of restarting from zero.
        self.recent_episodes: list[dict] = []
        # Finished training episodes per object id over the whole run (checkpointed).
        self.episodes_per_object: dict[str, int] = {}
        self.checkpoint_path = self.out / "checkpoints" / "last.pt"
        self._load()  # resumes from last.pt (or prev.pt beside it) when there is one
        if self.global_step == 0 and cfg.init_from:  # a new run of a curriculum
            self.agent.load_saved_state(init_agent_state(cfg.init_from), cfg.init_from)
        self.rollouts = self._make_rollouts(n_envs)

    def _make_rollouts(self, n_envs: int):
        """The run's collector: its envs in this process, stepped by the learner's own agent
        (workers 0), or on `workers` Ray workers that step their own envs with a CPU copy."""
        from corn_drake.rl.envs.vec_env import EnvBatch

        cfg = self.cfg
        # A resumed run's envs continue the object rounds where the run stopped (on average).
        start = sum(self.episodes_per_object.values()) // n_envs
        factory = run_env_factory(cfg.env, cfg.seed, cfg.workers, cfg.envs_per_worker, start)
        if cfg.workers > 0:
            from corn_drake.rl.workers.ray_workers import init_ray
            from corn_drake.rl.workers.segment_workers import RaySegmentCollectors

            init_ray(cfg.ray_address or None)
            return RaySegmentCollectors(factory, cfg.workers, cfg.envs_per_worker, self.agent)
        return SegmentCollector(EnvBatch(factory, cfg.envs_per_worker), self.agent, self.device)

    @property
    def envs(self):
        """The in-process env batch (EnvBatch): its envs, for tests and `bench train`."""
        return self.rollouts.envs

    # --- checkpoints -------------------------------------------------------------------------
    def _save(self, snapshot: Path | None = None) -> None:
        """The resumable checkpoint (last.pt, the one before it kept as prev.pt), or the same
        state as a kept `snapshot` file (no rotation: a resumed run that passes the same step
        again rewrites its snapshot and leaves prev.pt alone)."""
        # CPU tensors (loaded with map_location="cpu"): a run resumes on any device.
        state = {"agent": to_cpu(self.agent.state_dict()), "ppo": to_cpu(self.ppo.state_dict()),
                 "reward_scaler": self.reward_scaler.state_dict(),
                 **progress_state(self), "policy": self.cfg.policy}
        if snapshot is None:
            save_checkpoint(self.checkpoint_path, state)
        else:
            save_checkpoint(snapshot, state, keep_previous=False)

    def _snapshot_if_due(self, steps: int) -> None:
        """Keep checkpoints/step_NNNNNNNNN.pt when this update passed a multiple of
        snapshot_every env steps (the update's last step is the snapshot's step)."""
        every = self.cfg.snapshot_every
        if every and self.global_step // every > (self.global_step - steps) // every:
            self._save(snapshot_path(self.out, self.global_step))

    def _load(self) -> None:
        state = load_checkpoint(self.checkpoint_path, required=CHECKPOINT_KEYS)
        if state is None:
            return
        if state["policy"] != self.cfg.policy:
            raise InputError(f"{self.checkpoint_path} holds a {state['policy']!r} policy, "
                             f"not {self.cfg.policy!r}")
        self.agent.load_saved_state(state["agent"], self.checkpoint_path)
        self.ppo.load_state_dict(state["ppo"])
        self.reward_scaler.load_state_dict(state["reward_scaler"])
        restore_progress(self, state)

    # --- one update --------------------------------------------------------------------------
    def _collect(self) -> Rollout:
        """The update's segment, collected with this update's weights: the learner draws the
        unit noise for every env and step (the CPU generator, as one draw per step), the
        collector steps the envs, and the raw rewards are scaled here in step order."""
        T, n_envs, device = self.cfg.rollout_steps, len(self.rollouts), self.device
        action_dim = self.agent.log_std.shape[0]
        noise = torch.stack([torch.randn((n_envs, action_dim), generator=self.generator)
                             for _ in range(T)]).numpy()
        self.rollouts.sync(self.agent, self.update_index)
        segment = self.rollouts.collect(noise)
        if segment.version != self.update_index:
            raise RuntimeError(f"a segment acted with update {segment.version}'s weights in "
                               f"update {self.update_index}: PPO needs on-policy data")
        flat = {k: v.reshape(T * n_envs, *v.shape[2:]) for k, v in segment.obs.items()}
        obs = obs_to_tensors(flat, device)
        if segment.features is not None:
            obs["features"] = torch.as_tensor(
                segment.features.reshape(T * n_envs, *segment.features.shape[2:]), device=device)
        dones = segment.terminated | segment.truncated
        scaled = torch.stack([self.reward_scaler(torch.as_tensor(segment.rewards[t],
                                                                 dtype=torch.float32),
                                                 torch.as_tensor(dones[t])).float()
                              for t in range(T)])

        def tensor(x):
            return torch.as_tensor(np.asarray(x, np.float32), device=device)

        stack = {"actions": tensor(segment.actions), "logp": tensor(segment.logp),
                 "values": tensor(segment.values), "rewards": scaled.to(device),
                 "terminated": tensor(segment.terminated), "truncated": tensor(segment.truncated),
                 "final_values": tensor(segment.final_values)}
        return Rollout(obs, stack, tensor(segment.last_values), segment.episode_stats,
                       segment.sim_errors)

    def train(self, progress: bool = True) -> dict:
        from torch.utils.tensorboard import SummaryWriter
        from tqdm import tqdm

        self.out.mkdir(parents=True, exist_ok=True)
        writer = SummaryWriter(str(self.out / "tb"))
        cfg, n_envs = self.cfg, len(self.rollouts)
        trained = steps_trained(cfg.total_steps, self.global_step, n_envs * cfg.rollout_steps)
        if trained != cfg.total_steps:  # said, not rounded without a word (issue 63)
            print(f"--steps {cfg.total_steps} is trained as {trained}: whole rollouts of "
                  f"{n_envs} envs x {cfg.rollout_steps} steps", flush=True)
        bar = tqdm(total=cfg.total_steps, initial=self.global_step, disable=not progress,
                   desc=f"train {cfg.policy}", unit="step")
        while self.global_step < cfg.total_steps:
            t0 = time.perf_counter()
            rollout = self._collect()
            stack, flat_obs = rollout.stack, rollout.obs
            episodes, sim_errors = rollout.episodes, rollout.sim_errors
            adv, ret = compute_gae(stack["rewards"], stack["values"], stack["terminated"],
                                   stack["truncated"], stack["final_values"], rollout.last_values,
                                   cfg.ppo.gamma, cfg.ppo.gae_lambda)
            stats = self.ppo.update(flat_obs, stack["actions"].flatten(0, 1),
                                    stack["logp"].flatten(0, 1), adv.flatten(), ret.flatten(),
                                    self.generator)
            # Normalisers move after the update so collection and update saw the same inputs.
            self.agent.update_normalizer(flat_obs["context"])
            steps = cfg.rollout_steps * n_envs
            self.global_step += steps
            self.update_index += 1
            self.recent_episodes = recent = (self.recent_episodes + episodes)[-RECENT_EPISODES:]
            count_episodes_per_object(self.episodes_per_object, episodes)
            row = {"step": self.global_step, "update": self.update_index,
                   "steps_per_s": steps / (time.perf_counter() - t0), "kl": stats["kl"],
                   "lr": stats["lr"], "early_stop": stats["early_stop"],
                   # Optimiser steps this update took before the KL stop (epochs x minibatches
                   # when it never stops): the true amount of learning per update.
                   "gradient_steps": stats["minibatches"],
                   "critic_steps": stats["critic_steps"], "value_loss": stats["value"],
                   "episodes": len(episodes), "sim_errors": sim_errors,
                   "success_rate": float(np.mean([e["success"] for e in recent])) if recent else 0.0,
                   "return": float(np.mean([e["return"] for e in recent])) if recent else 0.0,
                   "episode_length": float(np.mean([e["length"] for e in recent])) if recent else 0.0}
            if hasattr(self.rollouts, "restarts"):
                row["worker_restarts"] = self.rollouts.restarts
            self.history.append(row)
            for key, value in row.items():
                if key not in ("step", "update"):
                    writer.add_scalar(f"train/{key}", value, self.global_step)
            bar.update(steps)
            bar.set_postfix(success=f"{row['success_rate']:.2f}", ret=f"{row['return']:.2f}")
            if not progress and self.update_index % 10 == 0:
                # Background runs log to a file: one line every ten updates instead of a bar.
                print(f"step {self.global_step}: success {row['success_rate']:.2f} return "
                      f"{row['return']:.3f} kl {row['kl']:.4f} lr {row['lr']:.2e} "
                      f"{row['steps_per_s']:.0f} steps/s", flush=True)
            if self.update_index % cfg.checkpoint_every == 0:
                self._save()
            self._snapshot_if_due(steps)
        self._save()
        writer.close()
        bar.close()
        metrics = {"policy": cfg.policy, "global_step": self.global_step,
                   "updates": self.update_index, "final": self.history[-1] if self.history else {},
                   "episodes_per_object": dict(sorted(self.episodes_per_object.items())),
                   "history": self.history}
        if hasattr(self.rollouts, "record"):  # Ray workers: where they ran, what died and why
            metrics.update(self.rollouts.record.report())
        write_json(self.out / "metrics.json", metrics)
        plot_learning_curves({cfg.policy: self.history}, self.out / "plots" / "learning_curve.png")
        return metrics
