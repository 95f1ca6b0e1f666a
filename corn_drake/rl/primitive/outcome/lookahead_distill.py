"""Distilling the one-step lookahead into the primitive agent: its critic learns what each
candidate primitive earned, as the simulator measured it, and its actor the best motion per
location under that critic.

Why: a one-step lookahead over the agent's own candidate primitives (rl/primitive/outcome/lookahead.py)
reaches push_turn's goals, the object at rest, in ~0.9 of unseen episodes where the TD3 policy
reaches ~0.13 (docs/results/primitive/, item 33). The primitives can do the task; TD3 with a
few thousand primitives does not learn to choose them. Every lookahead state gives the reward of
~50 primitives from one state, where a TD3 transition gives one: the critic is fitted to these
rewards directly (gamma 0: the lookahead is greedy in one primitive's reward, and that was
enough), and the greedy policy of a critic that predicts them well is the lookahead itself.

Data (collect_episode): at every state of an episode, the agent's features of the observation
(the frozen encoder's, agent.features) and every candidate's (location, motion, reward). The
episode goes on with the lookahead's best primitive, or with probability `follow_policy` with
the agent's own greedy one, so the states are both the lookahead's and the policy's (DAgger's
mixture).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from corn_drake.errors import InputError
from corn_drake.rl.primitive.outcome.lookahead import candidate_primitives, lookahead_step
from corn_drake.systems.low_push import push_contact

FEATURE_KEYS = ("tokens", "local", "global", "mask")


def collect_episode(env, agent, seed: int, random_motions: int, follow_policy: float,
                    rng: np.random.Generator) -> tuple[list[dict], dict]:
    """(states, outcome) of one episode of `env` (a PrimitiveEnv, no policy inside) from
    reset(seed): each state {"features": {key: (L, ...) float32}, "outcome": {"pose" (7: the
    object's [p, q_wxyz]), "goal" (7), "corners" (8, 3: its box keypoints, body frame), "aims"
    (L, 3: where the executor aims at each location), "physics" (5)}, and per candidate
    "location" (K,), "motion" (K, 3), "reward" (K,), "pose_after" (K, 7), "still_after" (K,),
    "success_after" (K,)}; outcome {"success", "primitives"}. The pose, goal, corners and
    poses after recompute the rewards (tests/test_lookahead_distill.py), so a model of the
    primitives' outcomes can be fitted to the same data."""
    if not 0.0 <= follow_policy <= 1.0:
        raise InputError(f"follow_policy must be in [0, 1], got {follow_policy}")
    obs, info = env.reset(seed=seed)
    states, status, primitives = [], info["status"], 0
    while True:
        features, _ = agent.features(obs)
        choice = agent.choose(obs)
        # What a model of the primitives' outcomes needs: where the object is, its goal and
        # its box keypoints (the reward's), besides every candidate's pose after.
        pose, goal = env.object_pose(), np.asarray(env.episode.goal_pose, float)
        corners = env.body_points("object_keypoints").astype(np.float64)
        # Where the executor aims for each location (a side push is lowered, low_push.py) and
        # the episode's physics (mass, frictions, restitution).
        aims = np.stack([push_contact(obs["cloud"], obs["normals"], int(i), env.primitive_cfg)[0]
                         for i in choice["candidates"]])
        candidates = candidate_primitives(choice, random_motions, rng)
        result = lookahead_step(env, candidates)
        states.append({"features": {k: features[k][0].numpy().astype(np.float32)
                                    for k in FEATURE_KEYS},
                       "outcome": {"pose": pose, "goal": goal, "corners": corners,
                                   "aims": aims, "physics": np.asarray(obs["physics"], float)},
                       "location": np.array([c[0] for c in candidates], np.int64),
                       "motion": np.array([c[2] for c in candidates], np.float32),
                       "reward": result.rewards.astype(np.float32),
                       "pose_after": result.poses.astype(np.float64),
                       "still_after": result.still.astype(bool),
                       "success_after": result.successes.astype(bool)})
        step = result.step
        if result.chosen != 0 and rng.random() < follow_policy:
            env.restore(result.start)  # the policy's own primitive instead (candidate 0)
            step = env.step({"point": candidates[0][1], "motion": candidates[0][2]})
        obs, _, terminated, truncated, info = step
        primitives += 1
        status = info.get("status", status)
        if terminated or truncated:
            return states, {"success": bool(status.get("success", 0) > 0),
                            "primitives": primitives}


def stack_states(states: list[dict]) -> dict[str, np.ndarray]:
    """The states as flat arrays: features per state (S, L, ...) and, when every state has
    them, its outcome parts (outcome_pose, outcome_goal, ...); candidates per row (state index,
    location, motion, reward, and pose_after, still_after, success_after with the outcomes)."""
    if not states:
        raise InputError("no lookahead states to stack")
    out = {f"features_{k}": np.stack([s["features"][k] for s in states]) for k in FEATURE_KEYS}
    out["state"] = np.concatenate([np.full(len(s["reward"]), i, np.int64)
                                   for i, s in enumerate(states)])
    for key in ("location", "motion", "reward"):
        out[key] = np.concatenate([s[key] for s in states])
    if all("outcome" in s for s in states):  # states collected with their outcomes
        for key in ("pose", "goal", "corners", "aims", "physics"):
            out[f"outcome_{key}"] = np.stack([s["outcome"][key] for s in states])
        for key in ("pose_after", "still_after", "success_after"):
            out[key] = np.concatenate([s[key] for s in states])
    return out


def _features(data: dict, index: torch.Tensor) -> dict[str, torch.Tensor]:
    return {k: torch.as_tensor(data[f"features_{k}"])[index] for k in FEATURE_KEYS}


def _q_at_rows(agent, data: dict, rows: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(q1, q2) of the critic for data rows `rows`: each row's motion at its own location."""
    states = torch.as_tensor(data["state"])[rows]
    at = torch.as_tensor(data["location"])[rows]
    # The heads score each location alone (primitive_heads.py), so each row is scored as a
    # state of one location, its own: the same values as scoring all L, L times cheaper.
    features = {"tokens": torch.as_tensor(data["features_tokens"])[states, at][:, None],
                "local": torch.as_tensor(data["features_local"])[states, at][:, None],
                "global": torch.as_tensor(data["features_global"])[states]}
    q1, q2 = agent.critic(features, torch.as_tensor(data["motion"])[rows][:, None, :])
    return q1[:, 0], q2[:, 0]


def critic_error(agent, data: dict[str, np.ndarray]) -> float:
    """Mean squared error of the agent's Q1 against the rows' rewards."""
    with torch.no_grad():
        q1, _ = _q_at_rows(agent, data, torch.arange(len(data["reward"])))
    return float(((q1 - torch.as_tensor(data["reward"])) ** 2).mean())


def choice_quality(agent, data: dict[str, np.ndarray]) -> dict[str, float]:
    """How well the agent's critic chooses among each state's candidates, in the rewards the
    simulator measured (mean over states): `chosen`, the candidate of highest Q1; `best`, the
    lookahead's; `first`, candidate 0 (the collecting policy's own choice); `mean`, a random
    candidate's expectation."""
    with torch.no_grad():
        q1 = _q_at_rows(agent, data, torch.arange(len(data["reward"])))[0].numpy()
    return scores_quality(q1, data)


def scores_quality(scores: np.ndarray, data: dict[str, np.ndarray]) -> dict[str, float]:
    """choice_quality's figures for any per-row `scores` (the highest-scored candidate of each
    state is the one chosen): a critic's Q, or a model's predicted reward."""
    figures = {"chosen": [], "best": [], "first": [], "mean": []}
    state, reward = data["state"], data["reward"]
    for i in np.unique(state):
        rows = np.flatnonzero(state == i)
        figures["chosen"].append(reward[rows[np.argmax(scores[rows])]])
        figures["best"].append(reward[rows].max())
        figures["first"].append(reward[rows[0]])
        figures["mean"].append(reward[rows].mean())
    return {k: float(np.mean(v)) for k, v in figures.items()}


def _rank_loss(q: torch.Tensor, reward: torch.Tensor, state: torch.Tensor,
               temperature: float) -> torch.Tensor:
    """Cross-entropy between each state's candidates ranked by reward (softmax of reward /
    temperature) and by `q` (softmax of q), averaged over the batch's states: only the order of
    one state's candidates matters, not their level."""
    losses = []
    for i in torch.unique(state):
        rows = state == i
        target = torch.softmax(reward[rows] / temperature, 0)
        losses.append(-(target * torch.log_softmax(q[rows], 0)).sum())
    return torch.stack(losses).mean()


def fit_critic(agent, data: dict[str, np.ndarray], epochs: int, batch_size: int = 256,
               lr: float = 3e-4, seed: int = 0, validation: dict | None = None,
               loss: str = "mse", temperature: float = 0.1) -> dict[str, list[float]]:
    """Fits both of the agent's Q heads to the candidates' rewards, every row once per epoch:
    `loss` "mse", their values; "rank", their order within each state (_rank_loss; batches of
    whole states, `batch_size` rows or so). Returns {"train": the mean loss per epoch,
    "validation": Q1's squared error on `validation` (held-out rows) after each epoch, when
    given}."""
    if loss not in ("mse", "rank"):
        raise InputError(f"fit_critic: loss must be 'mse' or 'rank', got {loss!r}")
    torch.manual_seed(seed)
    rows = len(data["reward"])
    optimiser = torch.optim.Adam(agent.critic.parameters(), lr=lr)
    state, reward = torch.as_tensor(data["state"]), torch.as_tensor(data["reward"])
    losses, held_out = [], []
    agent.critic.train()
    states = int(state.max()) + 1
    for _ in range(epochs):
        if loss == "rank":  # whole states per batch, in a random order
            order = torch.cat([torch.nonzero(state == i)[:, 0] for i in torch.randperm(states)])
        else:
            order = torch.randperm(rows)
        total = 0.0
        for start in range(0, rows, batch_size):
            batch = order[start:start + batch_size]
            q1, q2 = _q_at_rows(agent, data, batch)
            if loss == "rank":
                value = _rank_loss(q1, reward[batch], state[batch], temperature) + \
                    _rank_loss(q2, reward[batch], state[batch], temperature)
            else:
                value = nn.functional.mse_loss(q1, reward[batch]) + \
                    nn.functional.mse_loss(q2, reward[batch])
            optimiser.zero_grad()
            value.backward()
            optimiser.step()
            total += float(value.detach()) * len(batch)
        losses.append(total / rows)
        if validation is not None:
            agent.critic.eval()
            held_out.append(critic_error(agent, validation))
            agent.critic.train()
    agent.critic.eval()
    return {"train": losses, "validation": held_out}


def fit_actor(agent, data: dict[str, np.ndarray], epochs: int, batch_size: int = 64,
              lr: float = 3e-4, seed: int = 0) -> list[float]:
    """Fits the actor to the critic's best motion at every usable location of every state
    (the TD3 actor step, -Q1, over the collected states); returns -mean Q1 per epoch."""
    torch.manual_seed(seed)
    states = len(data["features_tokens"])
    optimiser = torch.optim.Adam(agent.actor.parameters(), lr=lr)
    for p in agent.critic.parameters():
        p.requires_grad_(False)
    losses = []
    agent.actor.train()
    try:
        for _ in range(epochs):
            order, total = torch.randperm(states), 0.0
            for start in range(0, states, batch_size):
                batch = order[start:start + batch_size]
                features = _features(data, batch)
                q1, _ = agent.critic(features, agent.actor(features))
                usable = features["mask"]
                loss = -(q1 * usable).sum() / usable.sum().clamp(min=1.0)
                optimiser.zero_grad()
                loss.backward()
                optimiser.step()
                total += float(loss.detach()) * len(batch)
            losses.append(total / states)
    finally:
        for p in agent.critic.parameters():
            p.requires_grad_(True)
        agent.actor.eval()
    return losses
