"""The real PPO trainer run for a benchmark, with its timed updates windowed (bench train, scale).

A benchmark builds a TrainConfig from the shared arguments (`add_trainer_arguments`,
`train_config`), and `run_trainer` trains it in a temporary folder with a randomly initialised
encoder (timing only) under a PhaseTimer (bench/phases.py): after `warmup_updates` untimed
updates (the first rollout and update pay torch's and the simulators' first calls: 2 s against
0.2 s in a probe here), each later update is one window, from entering the rollout to leaving
the PPO update. The first reset, TensorBoard, checkpoints and the normaliser update stay outside,
as in the trainer's own steps_per_s. Timers go on this run's instances only, so the trainer runs
its production code.
"""

from __future__ import annotations

from typing import Callable

from corn_drake.arguments.value_types import nonnegative_int, positive_int
from corn_drake.arguments.torch_threads import add_torch_threads_argument
from corn_drake.rl.policy_kinds import POLICY_KINDS

# The phases time_updates opens inside each window.
COLLECT, PPO_UPDATE = "collect", "ppo_update"


def add_trainer_arguments(parser) -> None:
    """The arguments every trainer benchmark takes (its env count is its own)."""
    parser.add_argument("--policy", default="corn", choices=POLICY_KINDS,
                        help="policy trained (a randomly initialised encoder: timing only)")
    parser.add_argument("--task", default="push",
                        help="task overlay: a name in diagrams/tasks/ or a YAML file")
    parser.add_argument("--updates", type=positive_int, default=3, help="PPO updates timed")
    parser.add_argument("--warmup-updates", type=nonnegative_int, default=1,
                        help="PPO updates run first, untimed (first calls into torch and the "
                             "simulators cost far more than later ones)")
    parser.add_argument("--rollout-steps", type=positive_int, default=32,
                        help="policy steps per env and update")
    parser.add_argument("--seed", type=nonnegative_int, default=0,
                        help="seed of the networks and the envs' episodes")
    add_torch_threads_argument(parser, "this run, as `train` takes it; the report records the "
                                       "count used")


def train_config(args, env_cfg, workers: int, envs_per_worker: int, device: str = "cpu"):
    """The TrainConfig of a benchmark run: warm-up plus timed updates of `args`, on `env_cfg`."""
    from corn_drake.config.training import TrainConfig

    per_update = max(workers, 1) * envs_per_worker * args.rollout_steps
    return TrainConfig(policy=args.policy, workers=workers, envs_per_worker=envs_per_worker,
                       total_steps=per_update * (args.warmup_updates + args.updates),
                       rollout_steps=args.rollout_steps, seed=args.seed, device=device,
                       env=env_cfg)


def time_updates(trainer, timer, warmup_updates: int = 0) -> None:
    """One timer window per update after the first `warmup_updates`: the rollout
    (trainer._collect) as phase COLLECT, the PPO update as PPO_UPDATE; what the window keeps
    for itself is the rest of the update (stacking the rollout, GAE)."""
    original_collect, original_update = trainer._collect, trainer.ppo.update
    started = [0]  # updates begun

    def collect(*args, **kwargs):
        started[0] += 1
        if started[0] > warmup_updates:
            timer.open_window()  # closed when this update's PPO step returns
        with timer.phase(COLLECT):
            return original_collect(*args, **kwargs)

    def update(*args, **kwargs):
        with timer.phase(PPO_UPDATE):
            result = original_update(*args, **kwargs)
        if timer.in_window:
            timer.close_window()
        return result

    trainer._collect, trainer.ppo.update = collect, update


def run_trainer(cfg, timer, warmup_updates: int,
                instrument: Callable | None = None) -> tuple[object, dict]:
    """(trainer, metrics) of `cfg` trained in a temporary folder, updates windowed on `timer`;
    `instrument(trainer)` adds a benchmark's own timers before training starts."""
    import tempfile

    from corn_drake.rl.pretrained_encoders import make_encoder
    from corn_drake.rl.training.ppo_trainer import Trainer

    with tempfile.TemporaryDirectory(prefix="bench_trainer_") as out:
        trainer = Trainer(cfg, out, make_encoder(cfg.policy))
        time_updates(trainer, timer, warmup_updates)
        if instrument is not None:
            instrument(trainer)
        metrics = trainer.train(progress=False)
    return trainer, metrics


def check_counts(timer, expected: dict[str, int]) -> None:
    """RuntimeError unless each phase was timed as often as expected: a trainer that no longer
    runs through the timed methods would otherwise give figures of nothing."""
    wrong = {name: timer.calls[name] for name, count in expected.items()
             if timer.calls[name] != count}
    if wrong:
        raise RuntimeError(f"timed {wrong}, expected {expected}: the trainer no longer runs "
                           "through the timed methods")


def trainer_logged_steps_per_s(history: list[dict], steps_per_update: int) -> float:
    """The trainer's own figure over `history` (its per-update timer), as a cross-check of the
    windows'."""
    return steps_per_update * len(history) / sum(steps_per_update / r["steps_per_s"]
                                                 for r in history)
