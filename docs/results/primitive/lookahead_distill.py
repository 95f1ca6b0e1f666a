"""The one-step lookahead distilled into a primitive policy (corn_drake/rl/primitive/outcome/lookahead_distill.py):
README.md's item 34.

    # lookahead states on the library's training objects (resumable: one file per --chunk episodes)
    .venv/bin/python docs/results/primitive/lookahead_distill.py collect \
        models/weights/push_turn_primitive --at-rest --episodes 120 --out runs/lookahead_data
    # the run's critic fitted to the candidates' rewards, its actor to that critic: a new run
    # folder that `corn-drake evaluate` reads like any primitive run
    .venv/bin/python docs/results/primitive/lookahead_distill.py fit \
        models/weights/push_turn_primitive --at-rest --data runs/lookahead_data \
        --out runs/prim_push_turn_distilled

Episode k of `collect` (k from --start) runs on the k-th training object (round-robin) with seed
5000 + k (not an evaluation seed). With --at-rest the env's success needs the object still at the end of a
primitive (PrimitiveConfig.success_at_rest), in the data and in the written run's config.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import torch

from corn_drake.assets.library import list_objects, load_object_spec
from corn_drake.rl.checkpoints import run_encoder_path
from corn_drake.rl.primitive.outcome.lookahead_distill import (choice_quality, collect_episode, critic_error,
                                             fit_actor, fit_critic, stack_states)
from corn_drake.rl.primitive.agent import load_primitive_run
from corn_drake.rl.envs.primitive_env import PrimitiveEnv
from corn_drake.run_folders.config_file import run_config_path
from corn_drake.storage.atomic_files import atomic_path, write_json, write_text
from corn_drake.storage.checkpoint_files import save_checkpoint

COLLECT_SEED = 5000


def collect(args) -> None:
    base, agent, _ = load_primitive_run(args.run)
    primitive = dataclasses.replace(agent.primitive_config, success_at_rest=args.at_rest,
                                    settle_steps=args.settle_steps)
    ids = list_objects(args.objects, "train")
    args.out.mkdir(parents=True, exist_ok=True)
    envs, outcomes = {}, []
    end = args.start + args.episodes
    for first in range(args.start, end, args.chunk):
        path = args.out / f"episodes_{first:05d}.npz"
        if path.exists():
            continue
        states, episodes, objects = [], [], []
        for k in range(first, min(first + args.chunk, end)):
            object_id = ids[k % len(ids)]
            if object_id not in envs:
                envs[object_id] = PrimitiveEnv(dataclasses.replace(base.env, seed=COLLECT_SEED),
                                               primitive, load_object_spec(args.objects,
                                                                           object_id))
            rng = np.random.default_rng(COLLECT_SEED + k)
            episode, outcome = collect_episode(envs[object_id], agent, COLLECT_SEED + k,
                                               args.random_motions, args.follow_policy, rng)
            states += episode
            episodes += [k] * len(episode)
            objects += [object_id] * len(episode)
            outcomes.append({"episode": k, "object": object_id, **outcome})
            print(json.dumps(outcomes[-1]), flush=True)
        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            np.savez(f, **stack_states(states), episode=np.array(episodes, np.int64),
                     object=np.array(objects))


def load_data(files: list[Path], object_tags: list[str] | None = None) -> dict[str, np.ndarray]:
    """The files' states and rows as one data dict; only the keys every file has (files
    collected before outcomes or objects were stored lack those). `object_tags`: per file, a
    prefix for its object ids (files of libraries whose ids coincide, told apart)."""
    parts = [dict(np.load(p)) for p in files]
    common = set.intersection(*(set(part) for part in parts))
    parts = [{k: v for k, v in part.items() if k in common} for part in parts]
    out, offset = {}, 0
    for i, part in enumerate(parts):  # each file's state indices follow the previous files'
        if object_tags is not None and "object" in part:
            part["object"] = np.array([object_tags[i] + o for o in part["object"]])
        part["state"] = part["state"] + offset
        offset += len(part["features_tokens"])
        for key, value in part.items():
            out.setdefault(key, []).append(value)
    return {key: np.concatenate(value) for key, value in out.items()}


def fit(args) -> None:
    base, agent, trained = load_primitive_run(args.run)
    files = sorted(f for folder in args.data for f in folder.glob("episodes_*.npz"))
    if len(files) <= args.holdout_files:
        raise SystemExit(f"--data {' '.join(map(str, args.data))}: {len(files)} data files, "
                         f"--holdout-files "
                         f"{args.holdout_files} leaves none to fit")
    held_out = load_data(files[-args.holdout_files:]) if args.holdout_files else None
    data = load_data(files[:len(files) - args.holdout_files])
    # The run's own critic first: its error and its choices on the held-out states.
    before = critic_error(agent, held_out) if held_out else None
    quality_before = choice_quality(agent, held_out) if held_out else None
    critic_losses = fit_critic(agent, data, args.critic_epochs, validation=held_out,
                               loss=args.critic_loss)
    quality_after = choice_quality(agent, held_out) if held_out else None
    actor_losses = fit_actor(agent, data, args.actor_epochs) if args.actor_epochs else []
    out = args.out
    (out / "checkpoints").mkdir(parents=True, exist_ok=True)
    config = run_config_path(Path(args.run)).read_text()
    encoder = Path(run_encoder_path(Path(args.run), base.encoder)).resolve()
    config = re.sub(r"(?m)^encoder: .*$", f"encoder: {encoder}", config)
    if args.at_rest:
        config = re.sub(r"(?m)^primitive:\n", "primitive:\n  success_at_rest: true\n", config)
    write_text(run_config_path(out), config)
    save_checkpoint(out / "checkpoints" / "last.pt",
                    {"agent": agent.network_state(), "global_step": trained})
    write_json(out / "distill_history.json",
               {"run": str(args.run), "data": [str(d) for d in args.data],
                "states": int(len(data["features_tokens"])), "rows": int(len(data["reward"])),
                "critic_loss": args.critic_loss, "critic_epochs": args.critic_epochs,
                "actor_epochs": args.actor_epochs, "held_out_files": args.holdout_files, "critic_held_out_error_before": before,
                "held_out_choice_quality_before": quality_before,
                "held_out_choice_quality_after": quality_after,
                "critic_loss_per_epoch": critic_losses["train"],
                "critic_held_out_error_per_epoch": critic_losses["validation"],
                "actor_loss_per_epoch": actor_losses})
    print(f"wrote {out}: {len(data['features_tokens'])} states, {len(data['reward'])} rows; "
          f"critic loss {critic_losses['train'][0]:.4f} -> {critic_losses['train'][-1]:.4f}; "
          f"held out {before} -> {critic_losses['validation']}; choices {quality_before} -> "
          f"{quality_after}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    c = sub.add_parser("collect")
    c.add_argument("run")
    c.add_argument("--objects", default="data/library")
    c.add_argument("--episodes", type=int, default=120)
    c.add_argument("--start", type=int, default=0,
                   help="the first episode's index (a later round's episodes follow an "
                        "earlier one's: other seeds)")
    c.add_argument("--chunk", type=int, default=10)
    c.add_argument("--random-motions", type=int, default=2)
    c.add_argument("--follow-policy", type=float, default=0.5)
    c.add_argument("--at-rest", action="store_true")
    c.add_argument("--settle-steps", type=int, default=0,
                   help="the executor waits up to this many periods after each primitive for "
                        "the object to come to rest (PrimitiveConfig.settle_steps)")
    c.add_argument("--out", type=Path, required=True)
    f = sub.add_parser("fit")
    f.add_argument("run")
    f.add_argument("--data", type=Path, nargs="+", required=True,
                   help="collect folders (their files in name order; the last ones held out)")
    f.add_argument("--critic-epochs", type=int, default=20)
    f.add_argument("--critic-loss", choices=("mse", "rank"), default="mse",
                   help="fit the rewards' values, or their order within each state")
    f.add_argument("--actor-epochs", type=int, default=20)
    f.add_argument("--holdout-files", type=int, default=1,
                   help="the last N data files are not fitted, only measured (the critic's "
                        "error on them after each epoch)")
    f.add_argument("--at-rest", action="store_true")
    f.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    torch.set_num_threads(1)
    collect(args) if args.command == "collect" else fit(args)


if __name__ == "__main__":
    main()
