"""`corn-drake bench learner`: seconds per PPO update at the batch sizes a many-core run makes.

A run on W workers x E envs x T rollout steps hands the learner one batch of W*E*T transitions
per update; at 100-1,000 cores that is 10^4-10^5 transitions, far above what one core collects,
so the learner's update time is what a cluster run waits on between segments (docs/many_core.md,
the paper-budget table). A real rollout of the policy (in-process envs, a randomly initialised
encoder: the cost depends on the batch's size, not its values) is tiled to each --batches size,
and PPO.update runs every epoch (the KL early stop off, so each batch pays the full update) once
untimed, then timed. The same-run baseline is the smallest batch: `per_transition_ratio` is each
batch's seconds per transition over the smallest's (1.0: the update scales linearly).
"""

from __future__ import annotations

from corn_drake.arguments.torch_threads import add_torch_threads_argument
from corn_drake.arguments.value_types import positive_int_list
from corn_drake.config.choices import POLICY_KINDS

NAME = "learner"
HELP = "PPO update seconds at the batch sizes of a many-core run, scaled to the smallest batch"


def add_arguments(parser):
    parser.add_argument("--policy", default="corn", choices=POLICY_KINDS,
                        help="policy whose update is timed (a randomly initialised encoder)")
    parser.add_argument("--task", default="push",
                        help="task overlay of the rollout: a name in diagrams/tasks/ or a YAML file")
    parser.add_argument("--batches", type=positive_int_list, default="1024,4096,16384",
                        help="transitions per update, comma-separated (W workers x E envs x T "
                             "steps of the run being planned)")
    parser.add_argument("--device", default="cpu", help="the learner's torch device (cpu, cuda)")
    add_torch_threads_argument(parser, "the learner, as `train` takes it; the report records "
                                       "the count used")


def run(args) -> dict:
    import tempfile
    import time

    import torch

    from corn_drake.config.plumbing.diagram_files import load_teacher_config
    from corn_drake.config.training import TrainConfig
    from corn_drake.nn.threads import torch_threads
    from corn_drake.rl.device import training_device
    from corn_drake.rl.training.ppo_trainer import Trainer
    from corn_drake.rl.pretrained_encoders import make_encoder

    env_cfg = load_teacher_config(args.task)
    env_cfg.check()
    training_device(args.device, "--device")
    cfg = TrainConfig(policy=args.policy, workers=0, envs_per_worker=2, rollout_steps=16,
                      total_steps=10**9, device=args.device, env=env_cfg)
    cfg.ppo.kl_stop_factor = 1e9  # every epoch runs: the update's full cost
    results = []
    with tempfile.TemporaryDirectory() as folder, torch_threads(args.torch_threads):
        threads = torch.get_num_threads()
        trainer = Trainer(cfg, folder, make_encoder(args.policy))
        rollout = trainer._collect()
        steps, envs = rollout.stack["actions"].shape[:2]
        base = steps * envs
        for batch in sorted(set(args.batches)):
            reps = -(-batch // base)  # whole rollouts, at least the batch asked for
            obs = {k: v.repeat(reps, *[1] * (v.dim() - 1)) for k, v in rollout.obs.items()}
            actions = rollout.stack["actions"].flatten(0, 1).repeat(reps, 1)
            logp = rollout.stack["logp"].flatten().repeat(reps)
            generator = torch.Generator().manual_seed(0)
            adv = torch.randn(reps * base, generator=generator)
            ret = torch.randn(reps * base, generator=generator)
            trainer.ppo.update(obs, actions, logp, adv, ret)  # untimed: first calls cost more
            start = time.perf_counter()
            trainer.ppo.update(obs, actions, logp, adv, ret)
            seconds = time.perf_counter() - start
            results.append({"batch": reps * base, "update_s": seconds,
                            "per_transition_us": 1e6 * seconds / (reps * base)})
            print(f"  batch {reps * base}: {seconds:.2f} s per update", flush=True)
    smallest = results[0]["per_transition_us"]
    for row in results:
        row["per_transition_ratio"] = row["per_transition_us"] / smallest
    return {"policy": args.policy, "task": args.task, "device": args.device,
            "torch_threads": threads, "epochs": cfg.ppo.epochs,
            "minibatches": cfg.ppo.minibatches, "results": results}
