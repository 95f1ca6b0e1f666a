"""Study: which training objective lets the learned 6D chooser pick better than its prior on
unseen states, with the labels there are (issue 61). Not product code: a fit that wins here
becomes an option of `corn-drake fit-chooser` only after it wins on episodes too.

    python experiments/chooser_objectives/compare.py --labels runs/fit_labels_r1 \
        --validate runs/validate_40_63.labels.jsonl.gz --updates 4000

Reads the label arrays `fit-chooser` caches (data/label_features), fits each variant on the
labels with the product's early stop on held-out train objects, and prints the validation
one-step reward of its picks (the prior's, the expert's and the best beside them).
"""

from __future__ import annotations

import argparse
import copy
import json
from pathlib import Path

import numpy as np
import torch
from torch import nn

from corn_drake.rl.imitation.dataset import load_label_arrays
from corn_drake.rl.imitation.fit import (BATCH_ROWS, HISTORY_EVERY, agreement, fit_value,
                                         inputs, split_objects, state_rows)
from corn_drake.rl.primitive.value_chooser.value_model import ValueNet


def fit_listwise(data: dict, tokens: bool, updates: int, seed: int, held: dict,
                 temperature: float, hidden: int = 256, weight_decay: float = 0.0) -> ValueNet:
    """The value net trained to rank each state's candidates: cross-entropy between the softmax
    of its predicted rewards and the softmax of the labelled rewards / temperature, per state;
    the value head as the product's (Huber on the beam's values). Early stop as the product's."""
    torch.manual_seed(seed)
    x = inputs(data, tokens)
    reward = torch.as_tensor(data["reward"], dtype=torch.float32)
    value = torch.as_tensor(data["value"], dtype=torch.float32)
    rows = [torch.as_tensor(r) for r in state_rows(data) if len(r) > 1]
    model = ValueNet(x.shape[1], hidden)
    model.standardise_by(x)
    optimiser = torch.optim.Adam(model.parameters(), lr=3e-4, weight_decay=weight_decay)
    best = (agreement(model.eval(), held, tokens, 4)["pick_reward"], 0,
            copy.deepcopy(model.state_dict()))
    model.train()
    per_batch = max(1, BATCH_ROWS // 30)  # ~30 candidates a state
    done = 0
    while done < updates:
        for batch in torch.randperm(len(rows)).split(per_batch):
            loss = 0.0
            for s in batch.tolist():
                r = rows[s]
                out = model(x[r])
                target = torch.softmax(reward[r] / temperature, 0)
                loss = loss - (target * torch.log_softmax(out[:, 0], 0)).sum()
                valued = ~torch.isnan(value[r])
                if valued.any():
                    loss = loss + nn.functional.huber_loss(out[valued, 1], value[r][valued],
                                                           delta=0.5)
            optimiser.zero_grad()
            (loss / len(batch)).backward()
            optimiser.step()
            done += 1
            if done % HISTORY_EVERY == 0:
                score = agreement(model.eval(), held, tokens, 4)["pick_reward"]
                model.train()
                if score > best[0]:
                    best = (score, done, copy.deepcopy(model.state_dict()))
            if done == updates:
                break
    model.load_state_dict(best[2])
    model.kept_update = best[1]
    return model.eval()


def write_run(model: ValueNet, out: Path, facts: dict) -> None:
    """A run folder choosing by `model`, as `fit-chooser` writes one (so `corn-drake evaluate`
    plays it on episodes)."""
    import dataclasses

    from corn_drake.rl.primitive.value_chooser.value_model import MODEL_FILE, save_value_model
    from corn_drake.rl.planner.sources import policy_run_folder
    from corn_drake.rl.primitive.outcome.model import MODEL_FILE as OUTCOME_FILE
    from corn_drake.rl.primitive.outcome.model_file import load_outcome_parts
    from corn_drake.rl.primitive.outcome.run_folder import outcome_run_config, write_outcome_run

    run_folder = policy_run_folder("models/weights/full6d_outcome")
    cfg = dataclasses.replace(outcome_run_config(run_folder, "full6d", []), chooser="expert_value")
    outcome = load_outcome_parts(run_folder / OUTCOME_FILE)
    kept = {k: v for k, v in outcome.facts.items() if k not in ("tokens", "inputs")}
    write_outcome_run(run_folder, cfg, outcome.model, outcome.facts["tokens"], kept, out,
                      more={MODEL_FILE: lambda path: save_value_model(path, model, **facts)})


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--labels", type=Path, required=True)
    parser.add_argument("--validate", type=Path, required=True)
    parser.add_argument("--objects", type=Path, default=Path("data/library_train"))
    parser.add_argument("--validate-objects", type=Path, default=Path("data/library_unseen"))
    parser.add_argument("--cache", type=Path, default=Path("data/label_features"))
    parser.add_argument("--updates", type=int, default=4000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--write-listwise", type=Path, default=None,
                        help="only fit the listwise variant without tokens (T 0.05) and write it "
                             "as a run folder here, for `corn-drake evaluate`")
    args = parser.parse_args()
    torch.set_num_threads(1)
    data = load_label_arrays([args.labels], args.objects, args.cache)
    val = load_label_arrays([args.validate], args.validate_objects, args.cache)
    fit, held = split_objects(data, 0.2, args.seed)
    if args.write_listwise is not None:
        model = fit_listwise(fit, False, args.updates, args.seed, held, 0.05)
        score = agreement(model, val, False, 4)
        facts = {"tokens": False, "beam": 4, "bank": 2, "updates": args.updates,
                 "seed": args.seed, "proposer": "models/weights/full6d_outcome",
                 "objective": "listwise softmax, temperature 0.05 (experiments/chooser_objectives)",
                 "states": int(len(data["chosen"])), "objects": int(len(set(data["object"]))),
                 "kept_update": model.kept_update, "validation": score}
        write_run(model, args.write_listwise, facts)
        print(f"wrote {args.write_listwise}: kept update {model.kept_update}, validation pick "
              f"reward {score['pick_reward']:.3f}")
        return
    rows = {}
    prior = agreement(ValueNet(data["x"].shape[1]).eval(), val, True, 4)
    rows["prior alone"] = (prior, 0)
    for tokens in (True, False):
        model = fit_value(fit, tokens, args.updates, args.seed, held=held)
        rows[f"pointwise Huber (product), tokens={tokens}"] = (
            agreement(model, val, tokens, 4), model.kept_update)
    for temperature in (0.05, 0.2):
        for tokens in (True, False):
            model = fit_listwise(fit, tokens, args.updates, args.seed, held, temperature)
            rows[f"listwise softmax T={temperature}, tokens={tokens}"] = (
                agreement(model, val, tokens, 4), model.kept_update)
    print(f"labels: {len(data['chosen'])} states, {len(set(data['object']))} objects; "
          f"validation: {int((val['chosen'] >= 0).sum())} searched states")
    print("| variant | kept update | validation agreement | pick reward (expert, best) |")
    print("| --- | --- | --- | --- |")
    for name, (a, kept) in rows.items():
        print(f"| {name} | {kept} | {a['agreement']:.2f} | {a['pick_reward']:.3f} "
              f"({a['expert_reward']:.3f}, {a['best_reward']:.3f}) |")
    print(json.dumps({k: v[0] for k, v in rows.items()}))


if __name__ == "__main__":
    main()
