"""`corn-drake bench primitive`: how fast the contact-primitive policy decides, acts and learns on
this machine, against the dense corn teacher's policy steps in the same run.

Three measurements, each after a few untimed warm-up rounds (the first calls into torch and the
simulator cost far more than later ones):
- decisions: a PrimitiveEnv (one step = one whole primitive, many policy periods) stepped with a
  PrimitiveAgent choosing greedily; the agent's choose() (encoder + per-location heads) and the
  env's step are timed apart, so the report gives the decision rate, the policy's forward time
  per decision and the policy periods each primitive took;
- TD3: TD3Learner.update on batches of the training batch size sampled from a replay filled with
  the features of the decisions' own observations (what the trainer stores), sampling included
  as the trainer pays it;
- baseline: the dense corn teacher (TeacherAgent, mean actions) stepping a TeacherEnv of the
  same task, object and seeds, one policy step per action, as the dense policies are trained
  and evaluated.
One env in this process for both, resets left out of the timing. The networks are randomly
initialised unless --encoder names a file: the pace, not the choices, is measured.

The ratios compare a decision with a dense policy step (`decisions_to_dense_steps`), the
primitive's policy periods with the dense steps (`periods_to_dense_steps`: above 1, a period of
the executor costs less than a dense step, whose network runs every period) and the two
policies' forward passes.

Imports of numpy, torch and Drake stay inside the functions: `corn-drake bench` imports every
module here to build its parser (tests/test_cli_startup.py).
"""

from __future__ import annotations

import time

from corn_drake.arguments.torch_threads import add_torch_threads_argument
from corn_drake.arguments.value_types import nonnegative_int, positive_int

NAME = "primitive"
HELP = ("contact-primitive decisions/s, its forward time and TD3 updates/s, against the dense "
        "corn teacher's policy steps/s (same run)")


def add_arguments(parser):
    parser.add_argument("--task", default="push",
                        help="task overlay: a name in diagrams/tasks/ or a YAML file (the "
                             "primitive env adds its layer, diagrams/primitive_rollout.yaml)")
    parser.add_argument("--decisions", type=positive_int, default=50,
                        help="primitives timed (each one decision of the policy)")
    parser.add_argument("--dense-steps", type=positive_int, default=500,
                        help="dense teacher policy steps timed (the baseline)")
    parser.add_argument("--updates", type=positive_int, default=200, help="TD3 updates timed")
    parser.add_argument("--warmup", type=nonnegative_int, default=2,
                        help="untimed rounds before each measurement (decisions, dense steps, "
                             "updates)")
    parser.add_argument("--batch-size", type=positive_int, default=None,
                        help="TD3 batch (default: the training default, PrimitiveTrainConfig)")
    parser.add_argument("--encoder", default="",
                        help="a CORN encoder file for both policies (default: randomly "
                             "initialised ones; the pace is the same)")
    parser.add_argument("--seed", type=nonnegative_int, default=0,
                        help="seed of the networks, the episodes and the replay batches")
    add_torch_threads_argument(parser, "this run, as `train` takes it; the report records the "
                                       "count used")


def _encoder(path: str):
    from corn_drake.rl.pretrained_encoders import load_encoder, make_encoder

    # allow_weak: a benchmark times the network, whatever its pretraining scored.
    return load_encoder("corn", path, allow_weak=True) if path else make_encoder("corn")


def _episode_seeds(seed: int):
    import numpy as np

    rng = np.random.default_rng(seed)
    while True:
        yield int(rng.integers(1 << 31))


def time_decisions(agent, env, rounds: int, warmup: int, seed: int, replay) -> dict:
    """Steps `env` (a PrimitiveEnv without a policy inside) for `warmup` + `rounds` greedy
    decisions of `agent`; the timed ones' totals. Every transition (warm-up ones too) goes into
    `replay` as the trainer stores it: per-location features of both observations."""
    import numpy as np

    seeds = _episode_seeds(seed)
    obs, _ = env.reset(seed=next(seeds))
    features = _features(agent, obs)
    forward = stepping = 0.0
    periods = episodes = 0
    for i in range(warmup + rounds):
        t0 = time.perf_counter()
        choice = agent.choose(obs)
        t1 = time.perf_counter()
        obs, reward, terminated, truncated, info = env.step(
            {"point": choice["point"], "motion": choice["motion"]})
        t2 = time.perf_counter()
        if i >= warmup:
            forward, stepping = forward + (t1 - t0), stepping + (t2 - t1)
            periods += int(info.get("ticks", 0))
        # A simulation error's observation is zeros (and ends the episode): not stored, as
        # nothing can be learnt from it.
        if "sim_error" not in info:
            next_features = _features(agent, obs)
            replay.add_batch(features, np.asarray([choice["location"]]),
                             np.asarray(choice["motion"], np.float32)[None],
                             np.asarray([reward]), np.asarray([terminated]), next_features)
            features = next_features
        if terminated or truncated or "sim_error" in info:
            episodes += i >= warmup
            obs, _ = env.reset(seed=next(seeds))
            features = _features(agent, obs)
    return {"seconds": forward + stepping, "forward_seconds": forward,
            "env_seconds": stepping, "periods": periods, "episodes_ended": episodes}


def _features(agent, obs) -> dict:
    features, _ = agent.features(obs)  # one observation: a batch of one
    return {k: v.cpu().numpy() for k, v in features.items()}


def time_updates(learner, replay, batch_size: int, rounds: int, warmup: int, seed: int) -> dict:
    """`warmup` + `rounds` TD3 updates on batches sampled from `replay`; the timed ones' totals
    (sampling included, as the trainer pays it; `update_seconds` alone)."""
    import numpy as np

    rng = np.random.default_rng(seed)
    total = update = 0.0
    for i in range(warmup + rounds):
        t0 = time.perf_counter()
        batch = replay.sample(batch_size, rng)
        t1 = time.perf_counter()
        learner.update(batch)
        t2 = time.perf_counter()
        if i >= warmup:
            total, update = total + (t2 - t0), update + (t2 - t1)
    return {"seconds": total, "update_seconds": update}


def time_dense(agent, env, rounds: int, warmup: int, seed: int) -> dict:
    """`warmup` + `rounds` policy steps of `env` (a TeacherEnv) with `agent`'s mean actions; the
    timed ones' totals."""
    seeds = _episode_seeds(seed)
    obs, _ = env.reset(seed=next(seeds))
    forward = stepping = 0.0
    for i in range(warmup + rounds):
        t0 = time.perf_counter()
        action = agent.act(obs)
        t1 = time.perf_counter()
        obs, _, terminated, truncated, _ = env.step(action)
        t2 = time.perf_counter()
        if i >= warmup:
            forward, stepping = forward + (t1 - t0), stepping + (t2 - t1)
        if terminated or truncated:
            obs, _ = env.reset(seed=next(seeds))
    return {"seconds": forward + stepping, "forward_seconds": forward}


def run(args) -> dict:
    import torch

    from corn_drake.config.plumbing.diagram_files import (load_primitive_env_config,
                                                          load_teacher_config)
    from corn_drake.config.primitive import PrimitiveTrainConfig
    from corn_drake.nn.threads import torch_threads
    from corn_drake.rl.ppo.agent import TeacherAgent
    from corn_drake.rl.envs.teacher_env import TeacherEnv
    from corn_drake.rl.primitive.agent import agent_for
    from corn_drake.rl.envs.primitive_env import PrimitiveEnv
    from corn_drake.rl.primitive.replay import ReplayBuffer
    from corn_drake.rl.primitive.td3 import TD3Learner, TD3Settings

    cfg = PrimitiveTrainConfig(env=load_primitive_env_config(args.task), seed=args.seed)
    if args.batch_size is not None:
        cfg.batch_size = args.batch_size
    cfg.check()
    dense_cfg = load_teacher_config(args.task)  # the dense teacher's own env, as it trains
    dense_cfg.check()
    with torch_threads(args.torch_threads):
        threads_used = torch.get_num_threads()
        torch.manual_seed(args.seed)
        agent = agent_for(cfg, _encoder(args.encoder)).eval()
        env = PrimitiveEnv(cfg.env, cfg.primitive)
        # Every decision's transition fits: none is overwritten before the updates sample it.
        replay = ReplayBuffer(args.warmup + args.decisions)
        decisions = time_decisions(agent, env, args.decisions, args.warmup, args.seed, replay)
        if len(replay) == 0:
            raise RuntimeError("every primitive ended in a simulation error: no transition to "
                               "train TD3 on")
        print(f"primitive: {args.decisions / decisions['seconds']:.2f} decisions/s")
        learner = TD3Learner(agent.actor, agent.critic, TD3Settings.for_run(cfg), seed=args.seed)
        updates = time_updates(learner, replay, cfg.batch_size, args.updates, args.warmup,
                               args.seed)
        print(f"TD3: {args.updates / updates['seconds']:.1f} updates/s "
              f"(batch {cfg.batch_size})")
        dense_agent = TeacherAgent("corn", _encoder(args.encoder)).eval()
        dense = time_dense(dense_agent, TeacherEnv(dense_cfg, spec=env.scene.object_spec),
                           args.dense_steps, args.warmup, args.seed)
        print(f"dense corn teacher: {args.dense_steps / dense['seconds']:.1f} policy steps/s")
    decision_rate = args.decisions / decisions["seconds"]
    period_rate = decisions["periods"] / decisions["seconds"]
    dense_rate = args.dense_steps / dense["seconds"]
    forward_ms = 1000 * decisions["forward_seconds"] / args.decisions
    dense_forward_ms = 1000 * dense["forward_seconds"] / args.dense_steps
    return {
        "primitive_decisions_per_s": decision_rate,
        "primitive_forward_ms_per_decision": forward_ms,
        "primitive_env_ms_per_decision": 1000 * decisions["env_seconds"] / args.decisions,
        "policy_periods_per_decision": decisions["periods"] / args.decisions,
        "primitive_policy_periods_per_s": period_rate,
        "td3_updates_per_s": args.updates / updates["seconds"],
        "td3_update_ms": 1000 * updates["update_seconds"] / args.updates,
        "dense_policy_steps_per_s": dense_rate,
        "dense_forward_ms_per_step": dense_forward_ms,
        "decisions_to_dense_steps": decision_rate / dense_rate,
        "periods_to_dense_steps": period_rate / dense_rate,
        "forward_primitive_to_dense": forward_ms / dense_forward_ms,
        "reference": "dense corn teacher: TeacherEnv + TeacherAgent mean actions, one env",
        "task": cfg.env.task.name, "object": env.scene.object_spec.name,
        "encoder": args.encoder or "random",
        "decisions": args.decisions, "dense_steps": args.dense_steps, "updates": args.updates,
        "warmup": args.warmup, "batch_size": cfg.batch_size, "replay_transitions": len(replay),
        "episodes_ended": decisions["episodes_ended"], "seed": args.seed,
        "torch_threads": threads_used,
    }
