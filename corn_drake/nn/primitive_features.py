"""Per-location features of the contact-primitive policy, from the frozen CORN encoder's tokens.

A location is where the policy may touch the object: one of the encoder's patch centres (16 per
cloud, each a cloud point; cloud points as locations measured no gain: config/retired.py). For
each location the policy sees
  tokens (D)  the patch token (the contact-pretrained encoder's summary of that part of the
              object, having attended to the hand token and every other patch);
  local (9)   the location relative to the object's origin, its goal flow (where the goal pose
              puts that surface point, minus where it is: HACMan's per-point goal flow), and
              its outward normal;
and per state
  global (146) the goal (relative position, 6D rotation), the hand (position relative to the
              object, 6D rotation) and the hand token.
Positions and flows are in decimetres (x 10) so they sit near unit scale beside the normals.
"""

from __future__ import annotations

import numpy as np
import torch

from corn_drake.nn.geometry import matrix_from_rot6d
from corn_drake.nn.encoders.patchify import gather_points, patch_indices

POSITION_SCALE = 10.0  # metres -> decimetres
# Where the goal sits in the features (location_features' layout): the rest does not depend on it.
_GLOBAL_GOAL = slice(0, 9)  # relative goal position (x POSITION_SCALE), then its 6D rotation
_LOCAL_REL = slice(0, 3)  # the location relative to the object's origin (x POSITION_SCALE)
_LOCAL_FLOW = slice(3, 6)  # its goal flow (x POSITION_SCALE)


def global_dim(token_dim: int) -> int:
    return 3 + 6 + 3 + 6 + token_dim


def _flow(rel, goal_position, goal_rotation):
    """Where the relative goal (position (B, 3), rotation (B, 3, 3)) puts each location
    (rel (B, L, 3), relative to the object's origin), minus where it is; numpy or torch."""
    return rel @ goal_rotation.swapaxes(-1, -2) + goal_position[:, None, :] - rel


def with_goal(features: dict[str, np.ndarray], goal_position: np.ndarray,
              goal_rotation: np.ndarray) -> dict[str, np.ndarray]:
    """The same states' features (numpy, batched, as location_features makes them) with another
    goal: `goal_position` (B, 3) the goal's position minus the object's (m, world frame) and
    `goal_rotation` (B, 3, 3) the goal's orientation times the object's transposed, as the
    observation's `goal` holds them. Tokens, locations, normals, the hand and the mask do not
    depend on the goal, so hindsight goals (rl/primitive/hindsight.py) need no encoder pass."""
    out = {k: np.array(v, copy=True) for k, v in features.items()}
    goal_position = np.asarray(goal_position, np.float64)
    goal_rotation = np.asarray(goal_rotation, np.float64)
    rel = out["local"][..., _LOCAL_REL].astype(np.float64) / POSITION_SCALE
    out["local"][..., _LOCAL_FLOW] = _flow(rel, goal_position, goal_rotation) * POSITION_SCALE
    out["global"][:, _GLOBAL_GOAL] = np.concatenate(
        [goal_position * POSITION_SCALE, goal_rotation[:, :, 0], goal_rotation[:, :, 1]], -1)
    return out


def location_features(encoder, obs: dict[str, torch.Tensor]
                      ) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
    """(features {"tokens" (B, L, D), "local" (B, L, 9), "global" (B, 146)}, candidates (B, L):
    each patch centre's index into the cloud) for a batch of primitive-env observations (torch,
    batched). `encoder`: a NormalizedEncoder of a patch kind."""
    cloud, hand = obs["cloud"], obs["hand_state"]
    network = encoder.network
    center_idx, knn_idx = patch_indices(cloud, network.num_patches, network.patch_size)
    tokens = encoder(cloud, hand, (center_idx, knn_idx))
    hand_token, patch_tokens = tokens[:, 0], tokens[:, 1:]
    p_obj, goal, normals = obs["object_position"], obs["goal"], obs["normals"]
    points = gather_points(cloud, center_idx)
    loc_normals = gather_points(normals, center_idx)
    R_rel = matrix_from_rot6d(goal[:, 3:9])  # goal rotation relative to the object's
    rel = points - p_obj.unsqueeze(1)
    flow = _flow(rel, goal[:, :3], R_rel)
    local = torch.cat([rel * POSITION_SCALE, flow * POSITION_SCALE, loc_normals], -1)
    context = torch.cat([goal[:, :3] * POSITION_SCALE, goal[:, 3:9],
                         (hand[:, :3] - p_obj) * POSITION_SCALE, hand[:, 3:9], hand_token], -1)
    return {"tokens": patch_tokens, "local": local, "global": context}, center_idx
