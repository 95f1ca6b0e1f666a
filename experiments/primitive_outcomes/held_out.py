"""What the held-out-object studies of this topic share: the seeded split of the objects, a model
fitted on some rows and measured on others, and how well per-candidate scores choose.

A model of the primitives' outcomes is only worth its place in the chooser if it carries to
objects it never saw (the evaluation's 200 episodes are on unseen objects), so every study here
holds objects out whole and scores the held-out states' choices in the rewards the simulator
measured for every candidate (the lookahead data of `corn-drake collect-outcomes`).
"""

from __future__ import annotations

import numpy as np
import torch

from corn_drake.rl.primitive.outcome.model import SCALE, fit_network


def held_out_objects(objects: list[str], count: int, split: int) -> tuple[list, list]:
    """(held-out objects, the others in a split's own order): split k's seeded shuffle."""
    order = list(np.random.default_rng(split).permutation(objects))
    return order[:count], order[count:]


def held_out_prediction(features, now, target, train, test, updates: int, seed: int):
    """(the prediction for rows `test`, its mean keypoint error in metres) of an outcome model
    fitted on rows `train` of `features` (fit_network, `updates` updates, `seed`)."""
    model = fit_network(features[train], now[train], target[train], updates, seed)
    with torch.no_grad():
        prediction = model(features[test], now[test])
    error = np.linalg.norm(prediction[0].numpy() - target[test].numpy(), axis=2).mean() / SCALE
    return prediction, float(error)


def scores_quality(scores: np.ndarray, data: dict[str, np.ndarray]) -> dict[str, float]:
    """How well per-row `scores` choose among each state's candidates (the highest-scored one is
    chosen), in the rewards the simulator measured, mean over states: `chosen`; `best`, the
    lookahead's; `first`, candidate 0 (the collecting policy's own choice); `mean`, a random
    candidate's expectation."""
    figures = {"chosen": [], "best": [], "first": [], "mean": []}
    state, reward = data["state"], data["reward"]
    for i in np.unique(state):
        rows = np.flatnonzero(state == i)
        figures["chosen"].append(reward[rows[np.argmax(scores[rows])]])
        figures["best"].append(reward[rows].max())
        figures["first"].append(reward[rows[0]])
        figures["mean"].append(reward[rows].mean())
    return {k: float(np.mean(v)) for k, v in figures.items()}
