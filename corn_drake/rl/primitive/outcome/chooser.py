"""The contact-primitive policy's choice made by the outcome model (rl/primitive/outcome/model.py) instead
of the critic: at every usable location the actor's motion and a fixed bank of uniform motions
are candidates, and the candidate of highest predicted reward is the one chosen. (An ensemble's
pessimism and a tilt classifier's veto or blend were tried and retired: config/retired.py.)

A run folder chooses this way when its config's `chooser` is "outcome_model"; the model is its
outcome_model.pt (rl/primitive/agent.load_primitive_run). The reward is predicted with the task
and progress_reward the agent is evaluated under (PrimitiveAgent.task, .primitive_config), so
`evaluate --task` and `--set primitive.*` reach the choice as they reach the env.
"""

from __future__ import annotations

import numpy as np
import torch

from corn_drake.rl.primitive.outcome.model import Candidates, model_inputs, predicted_rewards
from corn_drake.transforms import from_pose9

BANK = 32  # uniform motions tried at every location besides the actor's
BANK_SEED = 0  # the bank is one fixed set: the same observation gets the same choice


class OutcomeChooser:
    def __init__(self, model, tokens: bool, facts: dict | None = None):
        """`model`: the outcome model (eval mode); `facts`: what the model file says of itself
        (its data, updates), for reports."""
        self.model, self.tokens = model, bool(tokens)
        facts = dict(facts or {})
        # The fit's learning curve (outcome_model.fit_network's rows) goes to a shipped folder's
        # training_history.json, not into every report's facts.
        self.fit_history = list(facts.pop("fit_history", []))
        self.facts = {k: v for k, v in facts.items()
                      if isinstance(v, (int, float, str, bool, list))}
        self.input_kind = self.facts.setdefault("input_kind", "raw")  # model_inputs' kind
        self.facts["bank_motions"] = BANK
        self.bank = np.random.default_rng(BANK_SEED).uniform(-1.0, 1.0, (BANK, 3))

    def scores(self, candidates: Candidates, task, progress_reward: float) -> np.ndarray:
        """(R,) each candidate's predicted reward."""
        x, now, frames = model_inputs(candidates, self.tokens, self.input_kind)
        with torch.no_grad():
            return predicted_rewards(candidates, frames, self.model(x, now), task,
                                     progress_reward)

    def candidates(self, agent, obs: dict):
        """(Candidates, [(location, cloud point, motion)], which locations are usable (L,), every
        location's cloud point (L,)) for one observation."""
        features, points = agent.features(obs)
        with torch.no_grad():
            actor = agent.actor(features)[0].numpy().astype(np.float64)
        usable = features["mask"][0].numpy() > 0.5
        # No usable location (every pre-contact point under the table): all of them, as the
        # critic's choice then falls back to its argmax over all-masked scores.
        rows = [(int(location), int(points[0, location]), motion)
                for location in (np.flatnonzero(usable) if usable.any() else range(len(usable)))
                for motion in np.vstack([actor[location][None], self.bank])]
        return (candidates_of(agent, obs, features, rows), rows, usable,
                points[0].numpy())

    def choose(self, agent, obs: dict, task) -> dict:
        """PrimitiveAgent.choose's answer for one observation, chosen by predicted reward under
        `task` (the env config's TaskConfig) and the agent's progress_reward. A location's
        score is its best candidate's predicted reward; its motion, that candidate's."""
        candidates, options, usable, points = self.candidates(agent, obs)
        scores = self.scores(candidates, task, agent.primitive_config.progress_reward)
        best = int(np.argmax(scores))
        return choice_of(options, scores, best, usable, points)


def choice_of(rows: list, scores: np.ndarray, best: int, usable: np.ndarray,
              points: np.ndarray) -> dict:
    """PrimitiveAgent.choose's answer when candidate `best` of `rows` [(location, cloud point,
    motion)] is chosen: each location's score is its best candidate's (`scores`), its motion
    that candidate's."""
    location, point, motion = rows[best]
    per_location = np.full(len(usable), -np.inf)
    motions = np.zeros((len(usable), 3))
    for (loc, _, m), score in zip(rows, scores):
        if score > per_location[loc]:
            per_location[loc], motions[loc] = score, m
    # Locations never scored (ruled out) show as the lowest score, as the critic's choice.
    shown = np.where(np.isfinite(per_location), per_location,
                     per_location[np.isfinite(per_location)].min())
    return {"point": point, "motion": np.asarray(motion, np.float64), "location": location,
            "scores": shown, "usable": usable, "candidates": points, "motions": motions}


def candidates_of(agent, obs: dict, features: dict, rows: list) -> Candidates:
    """Candidates for `rows` [(location, cloud point, motion)] of one observation: each point's
    executor aim (low_push.push_contact, relative to the object's origin) and normal, the
    object's box keypoints, physics and goal, and the location's token (`features`:
    agent.features(obs)'s)."""
    from corn_drake.systems.control.low_push import push_contact

    p = np.asarray(obs["object_position"], np.float64)
    keypoints = np.asarray(obs["object_keypoints"], np.float64).reshape(-1, 3) - p
    goal_position, goal_rotation = from_pose9(np.asarray(obs["goal"], np.float64))
    aims = {}
    for _, point, _ in rows:
        if point not in aims:
            aims[point] = push_contact(obs["cloud"], obs["normals"], point,
                                       agent.primitive_config)[0] - p
    n = len(rows)
    return Candidates(
        aim=np.stack([aims[r[1]] for r in rows]),
        normal=np.stack([np.asarray(obs["normals"][r[1]], np.float64) for r in rows]),
        motion=np.stack([np.asarray(r[2], np.float64) for r in rows]),
        keypoints=np.repeat(keypoints[None], n, 0),
        physics=np.repeat(np.asarray(obs["physics"], np.float64)[None], n, 0),
        goal_rotation=np.repeat(goal_rotation[None], n, 0),
        goal_position=np.repeat(goal_position[None], n, 0),
        tokens=features["tokens"][0].numpy()[[r[0] for r in rows]])
