"""The contact-primitive policy's choice made by the outcome model (rl/primitive/outcome/model.py) instead
of the critic: at every usable location the actor's motion and a fixed bank of uniform motions
are candidates, and the candidate of highest predicted reward is the one chosen. With an
ensemble, the score is the members' mean reward less `outcome.pessimism` times their deviation;
with a tilt classifier and `outcome.tilt_veto` < 1, the candidates it expects to tip the object
are left out, and with `outcome.tilt_blend` every candidate's reward is its expectation under
the classifier's probability of a tilt (config/primitive.OutcomeChoiceConfig says why).

A run folder chooses this way when its config's `chooser` is "outcome_model"; the model is its
outcome_model.pt (rl/primitive_agent.load_primitive_run). The reward is predicted with the task
and progress_reward the agent is evaluated under (PrimitiveAgent.task, .primitive_config), so
`evaluate --task` and `--set primitive.*` reach the choice as they reach the env.
"""

from __future__ import annotations

import numpy as np
import torch

from corn_drake.errors import InputError
from corn_drake.rl.primitive.outcome.model import Candidates, model_inputs, predicted_rewards
from corn_drake.transforms import from_pose9

BANK = 32  # uniform motions tried at every location besides the actor's
BANK_SEED = 0  # the bank is one fixed set: the same observation gets the same choice


class OutcomeChooser:
    def __init__(self, models, tokens: bool, facts: dict | None = None, tilt=None):
        """`models`: one outcome model or a list of them (an ensemble); `tilt`: a
        rl/tilt_classifier.TiltClassifier or None; `facts`: what the model file says of itself
        (its data, updates), for reports. Chooses by the mean, no veto, until `use`."""
        self.models = list(models) if isinstance(models, (list, tuple)) else [models]
        self.tokens, self.tilt = bool(tokens), tilt
        facts = dict(facts or {})
        # The fit's learning curve (outcome_model.fit_network's rows) goes to a shipped folder's
        # training_history.json, not into every report's facts.
        self.fit_history = list(facts.pop("fit_history", []))
        self.facts = {k: v for k, v in facts.items()
                      if isinstance(v, (int, float, str, bool, list))}
        self.input_kind = self.facts.setdefault("input_kind", "raw")  # model_inputs' kind
        self.facts["bank_motions"] = BANK
        self.bank = np.random.default_rng(BANK_SEED).uniform(-1.0, 1.0, (BANK, 3))
        self.pessimism, self.tilt_veto, self.tilt_blend = 0.0, 1.0, False

    def use(self, choice) -> None:
        """Chooses as `choice` (a config/primitive.OutcomeChoiceConfig) says; InputError naming
        the setting the model file cannot serve."""
        if choice.pessimism > 0 and len(self.models) < 2:
            raise InputError(f"outcome.pessimism {choice.pessimism:g} needs an ensemble, and the "
                             "outcome model file holds one model (outcome_model.py fit "
                             "--members N)")
        if choice.tilt_veto < 1 and self.tilt is None:
            raise InputError(f"outcome.tilt_veto {choice.tilt_veto:g} needs a tilt classifier, "
                             "and the outcome model file has none (outcome_model.py fit --tilt)")
        if choice.tilt_blend and (self.tilt is None or "tilted_reward" not in self.facts):
            raise InputError("outcome.tilt_blend needs a tilt classifier and the reward its "
                             "data measured for tilts, and the outcome model file lacks them "
                             "(outcome_model.py fit --tilt)")
        self.pessimism, self.tilt_veto = float(choice.pessimism), float(choice.tilt_veto)
        self.tilt_blend = bool(choice.tilt_blend)
        self.facts.update(pessimism=self.pessimism, tilt_veto=self.tilt_veto,
                          tilt_blend=self.tilt_blend)

    def scores(self, candidates: Candidates, task, progress_reward: float) -> np.ndarray:
        """(R,) each candidate's score: the members' mean predicted reward (with tilt_blend,
        each member's expected under the classifier's tilt probability) less pessimism times
        their deviation, -inf where the tilt veto rules it out (unless it rules out all)."""
        x, now, frames = model_inputs(candidates, self.tokens, self.input_kind)
        with torch.no_grad():
            rewards = np.stack([predicted_rewards(candidates, frames, model(x, now), task,
                                                  progress_reward) for model in self.models], 1)
        if self.tilt_blend:
            p = self.tilt.probability(candidates)[:, None]
            rewards = (1.0 - p) * rewards + p * float(self.facts["tilted_reward"])
        # One model: its own rewards, bit for bit (the mean of one, a deviation of 0).
        scores = rewards.mean(1) - self.pessimism * rewards.std(1)
        if self.tilt_veto < 1.0:
            veto = self.tilt.probability(candidates) > self.tilt_veto
            if not veto.all():
                scores = np.where(veto, -np.inf, scores)
        return scores

    def candidates(self, agent, obs: dict):
        """(Candidates, [(location, cloud point, motion)], which locations are usable (L,), every
        location's cloud point (L,)) for one observation."""
        from corn_drake.systems.low_push import push_contact

        features, points = agent.features(obs)
        with torch.no_grad():
            actor = agent.actor(features)[0].numpy().astype(np.float64)
        usable = features["mask"][0].numpy() > 0.5
        p = np.asarray(obs["object_position"], np.float64)
        keypoints = np.asarray(obs["object_keypoints"], np.float64).reshape(-1, 3) - p
        goal_position, goal_rotation = from_pose9(np.asarray(obs["goal"], np.float64))
        rows = []
        # No usable location (every pre-contact point under the table): all of them, as the
        # critic's choice then falls back to its argmax over all-masked scores.
        for location in np.flatnonzero(usable) if usable.any() else range(len(usable)):
            point = int(points[0, location])
            aim = push_contact(obs["cloud"], obs["normals"], point, agent.primitive_config)[0] - p
            normal = np.asarray(obs["normals"][point], np.float64)
            for motion in np.vstack([actor[location][None], self.bank]):
                rows.append((int(location), point, motion, aim, normal))
        n = len(rows)
        # The model is told the push as the executor will make it: primitive.vertical_push
        # scales the motion's height (every outcome folder so far was collected at 1, where the
        # action and the push are the same).
        executed = np.array([1.0, 1.0, agent.primitive_config.vertical_push])
        candidates = Candidates(
            aim=np.stack([r[3] for r in rows]), normal=np.stack([r[4] for r in rows]),
            motion=np.stack([r[2] for r in rows]) * executed,
            keypoints=np.repeat(keypoints[None], n, 0),
            physics=np.repeat(np.asarray(obs["physics"], np.float64)[None], n, 0),
            goal_rotation=np.repeat(goal_rotation[None], n, 0),
            goal_position=np.repeat(goal_position[None], n, 0),
            tokens=features["tokens"][0].numpy()[[r[0] for r in rows]])
        return candidates, [(r[0], r[1], r[2]) for r in rows], usable, points[0].numpy()

    def choose(self, agent, obs: dict, task) -> dict:
        """PrimitiveAgent.choose's answer for one observation, chosen by predicted reward under
        `task` (the env config's TaskConfig) and the agent's progress_reward. A location's
        score is its best candidate's predicted reward; its motion, that candidate's."""
        candidates, options, usable, points = self.candidates(agent, obs)
        scores = self.scores(candidates, task, agent.primitive_config.progress_reward)
        best = int(np.argmax(scores))
        location, point, motion = options[best]
        per_location = np.full(len(usable), -np.inf)
        motions = np.zeros((len(usable), 3))
        for (loc, _, m), score in zip(options, scores):
            if score > per_location[loc]:
                per_location[loc], motions[loc] = score, m
        # Locations never scored (ruled out, or all their candidates vetoed) show as the lowest
        # score, as the critic's choice.
        shown = np.where(np.isfinite(per_location), per_location,
                         per_location[np.isfinite(per_location)].min())
        return {"point": point, "motion": np.asarray(motion, np.float64), "location": location,
                "scores": shown, "usable": usable, "candidates": points, "motions": motions}
