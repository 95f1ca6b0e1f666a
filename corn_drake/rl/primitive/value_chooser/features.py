"""What the learned chooser reads of one candidate primitive (value_model.ValueNet's inputs).

Per candidate, in the push's frame (the motion's heading turned to +x about the vertical, as
the outcome model's, so a push and the same push turned are one example), decimetres:
  - the object-relative contact numbers of outcome/model.box_contact_features (where on the
    box the push lands, the box's proportions, the normal, the motion, the physics);
  - the object's 8 box keypoints now and how far each is from its goal place (the goal is what
    the labels' values depend on; box_contact_features do not see it);
  - the mean keypoint distance to the goal, and the reward the proposing run's outcome model
    predicts for the candidate (a one-step prior the labels correct);
  - optionally the location's CORN patch token.
"""

from __future__ import annotations

import numpy as np
import torch

from corn_drake.rl.primitive.outcome.model import (PLANAR, SCALE, Candidates,
                                                   box_contact_features, push_frames, turn)

BOX_CONTACT_COLUMNS = 18  # box_contact_features: 13 object-relative numbers and 5 of physics
KEYPOINT_COLUMNS = 24  # the 8 box keypoints' xyz
BASE_FEATURES = BOX_CONTACT_COLUMNS + 2 * KEYPOINT_COLUMNS + 2  # + now, to goal, 2 scalars
PRIOR_COLUMN = BASE_FEATURES - 1  # the outcome model's predicted reward


def goal_points(c: Candidates) -> np.ndarray:
    """(R, 8, 3) the box keypoints at the goal, relative to the object's planar origin now."""
    return np.einsum("rij,rkj->rki", c.goal_rotation, c.keypoints) + \
        (c.goal_position * PLANAR)[:, None]


def candidate_features(c: Candidates, predicted: np.ndarray, tokens: bool) -> torch.Tensor:
    """(R, BASE_FEATURES [+ token size]) the chooser's inputs for candidates `c`, `predicted`
    (R,) the outcome model's reward of each."""
    frames = push_frames(c.motion)
    goal = goal_points(c)
    now = turn(frames, c.keypoints) * SCALE
    to_goal = turn(frames, goal - c.keypoints) * SCALE
    distance = np.linalg.norm(c.keypoints - goal, axis=2).mean(1) * SCALE
    parts = [box_contact_features(c).numpy().astype(np.float64),
             now.reshape(len(now), -1), to_goal.reshape(len(now), -1),
             distance[:, None], np.asarray(predicted, np.float64)[:, None]]
    if tokens:
        parts.append(np.asarray(c.tokens, np.float64))
    return torch.as_tensor(np.concatenate(parts, 1), dtype=torch.float32)
