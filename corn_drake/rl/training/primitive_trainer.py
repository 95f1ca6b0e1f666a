"""Off-policy training of the contact-primitive policy (`corn-drake train --policy primitive`).

Collection (rl/primitive/collection.py): every env runs primitives chosen by the current policy
(softmax over per-location scores + motion noise; the first `random_steps` primitives uniformly
random); the transitions go into the replay buffer as per-location features (the frozen encoder
runs once per observation, where the envs are), and the learner takes `updates_per_step` TD3
steps per primitive collected (rl/primitive/td3.py), on `--device`.
- In-process (`--workers 0`): one round (a primitive in every env) per loop, then its updates;
  a seed repeats a run exactly.
With `hindsight_goals` > 0 the collectors also relabel every finished episode with goals it
reached (rl/primitive/hindsight.py); those copies go into the replay too but are not counted as primitives.
- Ray (`--workers N`): each worker steps its own envs with its own copy of the networks, one
  round per request, asynchronously: the learner updates while the workers step
  (rl/workers/primitive_workers.py).

Run folder: config.yaml, encoder.pt (the frozen encoder, copied in so the folder is
self-contained), checkpoints/last.pt (+ prev.pt) and checkpoints/replay_<step>.npz, tb/
(TensorBoard), metrics.json (history rows every `log_every` primitives), plots/. A killed run
resumes from last.pt at the step it was saved: networks, targets, optimisers, replay, counters
and random streams come back; the envs start fresh episodes (the episode cut by the kill is not
replayed), continuing the rounds over the train objects. (Ray workers' own streams restart from
the seed and the step resumed at: a resumed Ray run goes on with new draws.)
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from corn_drake.config.primitive import PrimitiveTrainConfig
from corn_drake.contract import RECENT_EPISODES
from corn_drake.errors import InputError
from corn_drake.rl.checkpoints import env_hash
from corn_drake.rl.device import training_device
from corn_drake.rl.primitive.hindsight import HindsightRule
from corn_drake.rl.primitive.agent import agent_for
from corn_drake.rl.primitive.collection import Exploration, PrimitiveTransitions
from corn_drake.rl.primitive.replay import ReplayBuffer
from corn_drake.rl.run_progress import recent_mean, run_env_factory, to_cpu
from corn_drake.rl.primitive.td3 import TD3Learner, TD3Settings
from corn_drake.storage.atomic_files import write_json
from corn_drake.storage.checkpoint_files import load_checkpoint, previous_checkpoint, save_checkpoint

CHECKPOINT_KEYS = ("policy", "agent", "learner", "global_step", "episodes", "history",
                   "recent_episodes", "np_rng", "torch_rng", "replay_file")


def initial_agent(cfg: PrimitiveTrainConfig, encoder):
    """The weights a new run starts from: torch seeded with cfg.seed, then the untrained heads
    (what `make demo` evaluates as the untrained policy)."""
    torch.manual_seed(cfg.seed)
    return agent_for(cfg, encoder)


class PrimitiveTrainer:
    def __init__(self, cfg: PrimitiveTrainConfig, out: str | Path, encoder):
        self.cfg, self.out = cfg, Path(out)
        self.np_rng = np.random.default_rng(cfg.seed)
        self.agent = initial_agent(cfg, encoder)
        self.learner = TD3Learner(self.agent.actor, self.agent.critic, TD3Settings.for_run(cfg),
                                  device=training_device(cfg.device), seed=cfg.seed)
        self.replay = ReplayBuffer(cfg.replay_capacity)
        self.global_step, self.episodes, self.history = 0, 0, []
        self.recent_episodes: list[dict] = []
        self.checkpoint_dir = self.out / "checkpoints"
        self._load()
        if self.global_step == 0 and cfg.init_from:
            self._start_from(cfg.init_from)
        hindsight = HindsightRule.for_run(cfg.hindsight_goals, cfg.primitive, cfg.env.task)
        n_envs = max(cfg.workers, 1) * cfg.envs_per_worker
        factory = run_env_factory(cfg.env, cfg.seed, cfg.workers, cfg.envs_per_worker,
                                  self.episodes // n_envs, cfg.primitive)
        self.collector = self.workers = None
        if cfg.workers > 0:
            from corn_drake.rl.workers.primitive_workers import RayPrimitiveCollectors
            from corn_drake.rl.workers.ray_workers import init_ray

            init_ray(cfg.ray_address or None)
            self.workers = RayPrimitiveCollectors(factory, cfg.workers, cfg.envs_per_worker,
                                                  self.agent, cfg.seed, self.global_step,
                                                  hindsight)
        else:
            from corn_drake.rl.primitive.collection import PrimitiveCollector
            from corn_drake.rl.envs.vec_env import EnvBatch

            self.collector = PrimitiveCollector(EnvBatch(factory, cfg.envs_per_worker),
                                                self.agent, self.learner.select, hindsight)

    # --- checkpoints -------------------------------------------------------------------------
    def _save(self) -> None:
        """Replay first (its own file, named by step), then last.pt naming it: last.pt always
        names a complete replay file. Replay files of older checkpoints than prev.pt's go."""
        self.checkpoint_dir.mkdir(parents=True, exist_ok=True)
        replay_file = f"replay_{self.global_step:09d}.npz"
        self.replay.save(self.checkpoint_dir / replay_file)
        previous = load_checkpoint(self.checkpoint_dir / "last.pt", fallback=False)
        state = {"policy": self.cfg.policy, "agent": to_cpu(self.agent.network_state()),
                 "learner": to_cpu(self.learner.state_dict()), "global_step": self.global_step,
                 "episodes": self.episodes, "history": self.history,
                 "recent_episodes": self.recent_episodes, "np_rng": self.np_rng.bit_generator.state,
                 "torch_rng": torch.get_rng_state(), "replay_file": replay_file,
                 "env_sha256": env_hash(self.cfg)}
        # Saved again at the same step (a run's last save after its periodic one): last.pt is
        # rewritten in place, and prev.pt stays the step before with its own replay, so that a
        # damaged newest replay still has an older consistent pair to resume from.
        again = previous is not None and previous.get("global_step") == self.global_step
        save_checkpoint(self.checkpoint_dir / "last.pt", state, keep_previous=not again)
        if again:
            previous = load_checkpoint(previous_checkpoint(self.checkpoint_dir / "last.pt"),
                                       fallback=False)
        keep = {replay_file, (previous or {}).get("replay_file")}
        for path in self.checkpoint_dir.glob("replay_*.npz"):
            if path.name not in keep:
                path.unlink(missing_ok=True)

    def _load(self) -> None:
        # A replay write killed by SIGKILL leaves its temporary file (atomic_files.atomic_path):
        # this run holds the folder's lock, so none of them is being written now.
        for stale in self.checkpoint_dir.glob(".replay_*.npz.*.tmp"):
            stale.unlink(missing_ok=True)
        state = self._consistent_checkpoint()
        if state is None:
            return
        if state["policy"] != self.cfg.policy:
            raise InputError(f"{self.checkpoint_dir / 'last.pt'} holds a {state['policy']!r} "
                             f"policy, not {self.cfg.policy!r}")
        self.agent.load_network_state(state["agent"], self.checkpoint_dir / "last.pt")
        self.learner.load_state_dict(state["learner"])
        self.replay = state.pop("_replay")
        self.global_step, self.episodes = state["global_step"], state["episodes"]
        self.history, self.recent_episodes = state["history"], state["recent_episodes"]
        self.np_rng.bit_generator.state = state["np_rng"]
        torch.set_rng_state(state["torch_rng"])

    def _consistent_checkpoint(self) -> dict | None:
        """The newest checkpoint whose replay file reads too, with that replay as `_replay`:
        last.pt and its replay, else prev.pt and its (kept by _save for this), with a warning;
        None for a new run. A truncated newest replay (a full disk, a copy cut short) thus
        resumes from the pair before it, as an unreadable last.pt falls back to prev.pt."""
        import sys

        last = self.checkpoint_dir / "last.pt"
        problems = []
        for path, fallback in ((last, True), (previous_checkpoint(last), False)):
            if not path.is_file() and path != last:
                break
            state = load_checkpoint(path, required=CHECKPOINT_KEYS, fallback=fallback)
            if state is None:
                return None
            try:
                state["_replay"] = ReplayBuffer.load(self.checkpoint_dir / state["replay_file"],
                                                     self.cfg.replay_capacity)
            except InputError as e:  # a missing or unreadable replay file
                problems.append(str(e))
                continue
            if problems:
                print(f"warning: {problems[0]}; resuming from the previous checkpoint {path} "
                      f"(step {state['global_step']}) and its replay", file=sys.stderr)
            return state
        raise InputError(f"{self.checkpoint_dir}: no checkpoint with a readable replay file: "
                         + "; ".join(problems))

    def _start_from(self, run: str) -> None:
        """A new run's actor and critic (and their targets) from another primitive run's
        checkpoint; optimisers, replay and counters stay fresh."""
        from corn_drake.errors import MissingInputError

        path = Path(run) / "checkpoints" / "last.pt"
        state = load_checkpoint(path, required=("agent",))
        if state is None:
            raise MissingInputError(f"--init-from {run}: no checkpoint ({path})")
        self.agent.load_network_state(state["agent"], path)
        self.learner.actor_target.load_state_dict(self.agent.actor.state_dict())
        self.learner.critic_target.load_state_dict(self.agent.critic.state_dict())

    # --- collection ----------------------------------------------------------------------------
    def _exploration(self, step: int) -> Exploration:
        """How primitive number `step` of the run is chosen."""
        cfg = self.cfg
        return Exploration(random=step < cfg.random_steps, temperature=cfg.temperature,
                           motion_noise=cfg.motion_noise)

    def _round(self) -> PrimitiveTransitions:
        """In-process: one primitive in every env, chosen with the trainer's own stream."""
        return self.collector.collect(1, self._exploration(self.global_step), self.np_rng)

    def _arrivals(self):
        """Transitions as they are collected: in-process one round at a time; with Ray
        workers, whichever worker's round comes back first, that worker being sent its next
        round (acting with the weights as they are then) before the learner updates on it."""
        if self.workers is None:
            while True:
                yield self._round()
        workers, submitted = self.workers, self.global_step
        workers.publish(self.agent, self.learner.updates)
        for w in workers.idle_workers():
            workers.submit(w, 1, self._exploration(submitted))
            submitted += workers.envs_per_worker
        while True:
            w, transitions = workers.next_ready()
            workers.publish(self.agent, self.learner.updates)
            workers.submit(w, 1, self._exploration(submitted))
            submitted += workers.envs_per_worker
            yield transitions

    def _store(self, t: PrimitiveTransitions) -> None:
        for part in (t, t.relabeled):  # the hindsight copies after the primitives themselves
            if part is not None:
                self.replay.add_batch(part.features, part.locations, part.motions, part.rewards,
                                      part.terminated, part.next_features)

    def train(self, progress: bool = True) -> dict:
        from torch.utils.tensorboard import SummaryWriter
        from tqdm import tqdm

        from corn_drake.viz.learning_curves import plot_learning_curves

        cfg = self.cfg
        self.out.mkdir(parents=True, exist_ok=True)
        writer = SummaryWriter(str(self.out / "tb"))
        bar = tqdm(total=cfg.total_steps, initial=self.global_step, disable=not progress,
                   desc="train primitive", unit="primitive")
        losses: list[dict] = []
        window = {"t0": time.perf_counter(), "primitives": 0}
        last_log = self.global_step // cfg.log_every
        last_checkpoint = self.global_step // cfg.checkpoint_every
        arrivals = self._arrivals()
        started = self.global_step
        while self.global_step < cfg.total_steps:
            transitions = next(arrivals)
            self._store(transitions)
            n = len(transitions)
            self.global_step += n
            window["primitives"] += n
            for stats in transitions.episode_stats:
                self.episodes += 1
                self.recent_episodes = (self.recent_episodes + [stats])[-RECENT_EPISODES:]
            if len(self.replay) >= cfg.learning_starts:
                for _ in range(cfg.updates_per_step * n):
                    losses.append(self.learner.update(self.replay.sample(cfg.batch_size,
                                                                         self.np_rng)))
            bar.update(n)
            if self.global_step // cfg.log_every > last_log:
                last_log = self.global_step // cfg.log_every
                self._log(writer, losses, window, bar, progress)
                losses = []
                window = {"t0": time.perf_counter(), "primitives": 0}
            if self.global_step // cfg.checkpoint_every > last_checkpoint:
                last_checkpoint = self.global_step // cfg.checkpoint_every
                self._save()
        self._save()
        if self.global_step > cfg.total_steps > started:
            # Said, not rounded without a word (issue 63): a round is one primitive per env.
            print(f"--steps {cfg.total_steps} trained as {self.global_step}: whole rounds of "
                  "one primitive per env", flush=True)
        where = {}
        if self.workers is not None:  # where the workers ran, what died and why
            where = self.workers.record.report()
            self.workers.close()
        writer.close()
        bar.close()
        metrics = {"policy": cfg.policy, "global_step": self.global_step,
                   "episodes": self.episodes, "final": self.history[-1] if self.history else {},
                   "history": self.history, **where}
        write_json(self.out / "metrics.json", metrics)
        if self.history:
            plot_learning_curves({cfg.policy: self.history},
                                 self.out / "plots" / "learning_curve.png", steps="primitives")
        return metrics

    def _log(self, writer, losses, window, bar, progress) -> None:
        recent = self.recent_episodes
        elapsed = time.perf_counter() - window["t0"]
        row = {"step": self.global_step, "episodes": self.episodes,
               "success_rate": recent_mean(recent, "success"),
               "return": recent_mean(recent, "return"),
               "episode_length": recent_mean(recent, "length"),
               "primitives_per_s": window["primitives"] / max(elapsed, 1e-9),
               "replay": len(self.replay), "updates": self.learner.updates}
        if self.workers is not None:  # as the PPO trainer's rows
            row["worker_restarts"] = self.workers.restarts
        for key in ("critic_loss", "actor_loss", "q_mean"):
            values = [x[key] for x in losses if np.isfinite(x.get(key, np.nan))]
            row[key] = float(np.mean(values)) if values else None
        self.history.append(row)
        for key, value in row.items():
            if key != "step" and value is not None:
                writer.add_scalar(f"train/{key}", value, self.global_step)
        writer.flush()
        bar.set_postfix(success=f"{row['success_rate']:.2f}", ret=f"{row['return']:.2f}")
        if not progress:
            print(f"primitive {self.global_step}: success {row['success_rate']:.2f} return "
                  f"{row['return']:.3f} critic {row['critic_loss']} "
                  f"{row['primitives_per_s']:.1f} primitives/s", flush=True)
