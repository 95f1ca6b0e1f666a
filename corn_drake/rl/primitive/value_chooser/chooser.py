"""The learned 6D chooser at run time: no simulator, only the run's networks.

At every state the proposing run (its actor, re-chosen per location by its outcome model:
rl/primitive/outcome/chooser.OutcomeChooser) gives one motion per usable location, and `bank`
fixed uniform motions are tried at every usable location besides, as the expert's candidates
are (the run's motion plus uniform ones). Each candidate's features (features.py) go through
the value network; the choice is value_model.choose_index's (the expert's rule on predictions).

A run folder chooses this way when its config's `chooser` is "expert_value"; its
chooser_value.pt is the network (rl/primitive/agent.load_primitive_run).
"""

from __future__ import annotations

import numpy as np
import torch

from corn_drake.rl.primitive.value_chooser.features import candidate_features
from corn_drake.rl.primitive.value_chooser.value_model import choose_index
from corn_drake.rl.primitive.outcome.chooser import candidates_of, choice_of

BANK_SEED = 1  # one fixed bank: the same observation gets the same choice


class ValueChooser:
    def __init__(self, model, facts: dict, inner):
        """`model`: value_model.ValueNet (eval mode); `facts`: its file's entries (tokens, beam,
        bank, the labels it was fitted to); `inner`: the proposing run's OutcomeChooser."""
        self.model, self.inner = model, inner
        self.fit_history = list(facts.get("fit_history", []))
        self.facts = {k: v for k, v in facts.items() if k != "fit_history"
                      and isinstance(v, (int, float, str, bool, list))}
        self.tokens, self.beam = bool(facts["tokens"]), int(facts["beam"])
        self.bank = np.random.default_rng(BANK_SEED).uniform(-1.0, 1.0, (int(facts["bank"]), 3))

    def choose(self, agent, obs: dict, task) -> dict:
        """PrimitiveAgent.choose's answer for one observation (as OutcomeChooser.choose's, with
        each location's score its best candidate's predicted value)."""
        proposed = self.inner.choose(agent, obs, task)
        usable = proposed["usable"]
        locations = np.flatnonzero(usable) if usable.any() else range(len(usable))
        points = proposed["candidates"]
        rows = [(int(loc), int(points[loc]), motion) for loc in locations
                for motion in np.vstack([proposed["motions"][loc][None], self.bank])]
        features, _ = agent.features(obs)
        c = candidates_of(agent, obs, features, rows)
        predicted = self.inner.scores(c, task, agent.primitive_config.progress_reward)
        with torch.no_grad():
            out = self.model(candidate_features(c, predicted, self.tokens)).numpy()
        best = choose_index(out[:, 0], out[:, 1], self.beam)
        return choice_of(rows, out[:, 1], best, usable, points)
