"""Fitting the learned chooser (value_model.ValueNet) to label arrays (dataset.py), and how its
choices compare with the expert's on labelled states no simulator is asked about.

The loss is the Huber loss of the predicted reward on every candidate plus that of the predicted
value on the candidates the expert's beam valued; Adam, batches of BATCH_ROWS candidates. One
thread and the same arrays, seed and updates give the same weights.
"""

from __future__ import annotations

import copy

import numpy as np
import torch
from torch import nn

from corn_drake.rl.primitive.value_chooser.features import BASE_FEATURES
from corn_drake.rl.primitive.value_chooser.value_model import ValueNet, choose_index

BATCH_ROWS = 256
ROW_KEYS = ("x", "reward", "value")  # dataset.py's per-candidate arrays ("state" besides)
STATE_KEYS = ("object", "drift")  # its per-state arrays ("chosen" besides)
HISTORY_EVERY = 100  # updates per row of the fit's learning curve (and per early-stop check)


def inputs(data: dict, tokens: bool) -> torch.Tensor:
    """The feature columns a chooser with or without tokens reads."""
    x = data["x"] if tokens else data["x"][:, :BASE_FEATURES]
    return torch.as_tensor(np.asarray(x, np.float32))


def split_objects(data: dict, fraction: float, seed: int) -> tuple[dict, dict]:
    """(the states of all but a seeded `fraction` of data's objects (at least one held), the
    states of those held out): the early stop's held-out part."""
    objects = sorted(set(data["object"]))
    held = set(np.random.default_rng(seed).permutation(objects)[
        :max(1, int(round(fraction * len(objects))))])
    keep = np.array([o not in held for o in data["object"]])
    return select_states(data, np.flatnonzero(keep)), select_states(data, np.flatnonzero(~keep))


def select_states(data: dict, states: np.ndarray) -> dict:
    """The arrays of `states` (indices), their rows with them, renumbered."""
    number = np.full(len(data["chosen"]), -1)
    number[states] = np.arange(len(states))
    rows = np.flatnonzero(number[data["state"]] >= 0)
    row_number = np.full(len(data["state"]), -1)
    row_number[rows] = np.arange(len(rows))
    chosen = data["chosen"][states]
    out = {k: v[rows] for k, v in data.items() if k in ROW_KEYS}
    out.update({k: v[states] for k, v in data.items() if k in STATE_KEYS})
    out.update(state=number[data["state"][rows]],
               chosen=np.where(chosen >= 0, row_number[np.maximum(chosen, 0)], -1))
    return out


def fit_value(data: dict, tokens: bool, updates: int, seed: int, hidden: int = 256,
              history: list | None = None, held: dict | None = None,
              beam: int = 4) -> ValueNet:
    """A ValueNet fitted to every row of `data`; `history` (a list) gets {"update", "loss"}
    every HISTORY_EVERY updates. Given `held` (states of other objects), the weights kept are
    those whose picks there earned the most one-step reward, checked every HISTORY_EVERY updates
    and before the first (the prior alone): with few labels the network overfits its objects
    and picks worse than its prior on others (measured: 4,000 updates on 10 objects, 0.158
    against the prior's 0.235 on gate B's unseen states)."""
    torch.manual_seed(seed)
    x = inputs(data, tokens)
    reward = torch.as_tensor(data["reward"], dtype=torch.float32)
    value = torch.as_tensor(data["value"], dtype=torch.float32)
    valued = ~torch.isnan(value)
    model = ValueNet(x.shape[1], hidden)
    model.standardise_by(x)
    optimiser = torch.optim.Adam(model.parameters(), lr=3e-4)
    done, window = 0, []
    best = None
    if held is not None:
        best = (agreement(model.eval(), held, tokens, beam)["pick_reward"], 0,
                copy.deepcopy(model.state_dict()))
        model.train()
    while done < updates:
        for batch in torch.randperm(len(x)).split(BATCH_ROWS):
            out = model(x[batch])
            loss = nn.functional.huber_loss(out[:, 0], reward[batch], delta=0.5)
            mask = valued[batch]
            if mask.any():
                loss = loss + nn.functional.huber_loss(out[mask, 1], value[batch][mask],
                                                       delta=0.5)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            done += 1
            window.append(loss.item())
            if done % HISTORY_EVERY == 0 or done == updates:
                row = {"update": done, "loss": float(np.mean(window))}
                window = []
                if best is not None:
                    row["held_pick_reward"] = agreement(model.eval(), held, tokens,
                                                        beam)["pick_reward"]
                    model.train()
                    if row["held_pick_reward"] > best[0]:
                        best = (row["held_pick_reward"], done, copy.deepcopy(model.state_dict()))
                if history is not None:
                    history.append(row)
            if done == updates:
                break
    if best is not None:
        model.load_state_dict(best[2])
        model.kept_update = best[1]
    return model.eval()


def picks(model: ValueNet, data: dict, tokens: bool, beam: int) -> np.ndarray:
    """(S,) the row the chooser picks at every state of `data`, among that state's labelled
    candidates."""
    with torch.no_grad():
        out = model(inputs(data, tokens)).numpy()
    return np.array([rows[choose_index(out[rows, 0], out[rows, 1], beam)]
                     for rows in state_rows(data)])


def state_rows(data: dict) -> list[np.ndarray]:
    """Each state's row indices, found in one pass (a scan of every row per state made the
    early stop's checks quadratic in the labels)."""
    order = np.argsort(data["state"], kind="stable")
    bounds = np.searchsorted(data["state"][order], np.arange(len(data["chosen"]) + 1))
    return [order[a:b] for a, b in zip(bounds[:-1], bounds[1:])]


def agreement(model: ValueNet, data: dict, tokens: bool, beam: int) -> dict:
    """How the chooser's picks compare with the expert's at `data`'s states: the share where it
    picks the expert's candidate; the mean reward of its pick against the expert's and against
    the best one-step reward there; the share of picks the expert valued (in its beam)."""
    searched = data["chosen"] >= 0  # the states the expert chose at (not those reached)
    chosen = picks(model, data, tokens, beam)[searched]
    expert = data["chosen"][searched]
    reward, value = data["reward"], data["value"]
    rows_of = state_rows(data)
    best = np.array([reward[rows_of[s]].max() for s in np.flatnonzero(searched)])
    return {"states": int(len(chosen)),
            "agreement": float(np.mean(chosen == expert)),
            "pick_reward": float(np.mean(reward[chosen])),
            "expert_reward": float(np.mean(reward[expert])),
            "best_reward": float(np.mean(best)),
            "pick_in_beam": float(np.mean(~np.isnan(value[chosen])))}
