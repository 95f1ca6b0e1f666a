"""A model of what a contact primitive does to the object, and the reward it predicts.

Why (the primitive results log, item 35): a critic must learn a primitive's reward for one
goal, but that reward is a known function of where the primitive leaves the object: the
progress_reward times how much it closes the mean distance between the object's box keypoints
and the goal's, plus the task's success reward. So this model predicts only the object's motion,
which does not depend on the goal, and the reward follows by the env's own rule. Measured on
held-out training objects it chooses better than the critic fitted to the same data (0.060
against 0.025 per primitive).

Inputs, per candidate primitive: the executor's aim point (relative to the object's origin), the
surface normal, the push motion ([-1, 1]^3), the object's 8 box keypoints at its current pose
(relative to its origin), the episode's physics (mass, frictions, restitution) and optionally
the location's contact token. Outputs: the object's planar displacement and rotation vector.
Inputs and outputs are in the push's frame (the motion's heading turned to +x about the
vertical), so a push and the same push turned about the vertical are one example. A model of
input kind "box_contact" reads object-relative numbers instead (box_contact_features: the aim's
height as a fraction of the box's, the box's proportions along and across the push...).

The data are `corn-drake collect-outcomes` folders whose states hold their outcomes
(rl/primitive/outcome/collect.collect_episode); `corn-drake fit-outcome` fits the model
(outcome/fit.py); outcome_model.pt files are rl/primitive/outcome/model_file.py's.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch
from torch import nn

from corn_drake.transforms import quat_wxyz_to_matrix

SCALE = 10.0  # metres -> decimetres, as the policy's features
PLANAR = np.array([1.0, 1.0, 0.0])  # the reward's keypoints drop the origin's height
BATCH_ROWS = 256  # candidates per update
HISTORY_EVERY = 100  # updates per row of a fit's learning curve (fit_network)
# The collected arrays a fit needs: per state, then per candidate.
OUTCOME_KEYS = ("outcome_pose", "outcome_goal", "outcome_corners", "outcome_aims",
                "outcome_physics")
OUTCOME_ROW_KEYS = ("pose_after", "still_after", "success_after")
# What an outcome model reads (model_inputs): the candidate's own numbers, or object-relative
# ones; files from before input kinds were recorded are "raw".
INPUT_KINDS = ("raw", "box_contact")
MODEL_FILE = "outcome_model.pt"  # in a run folder whose config's chooser is "outcome_model"


@dataclasses.dataclass
class Candidates:
    """R candidate primitives, each with what the model and the reward need (world frame)."""
    aim: np.ndarray  # (R, 3) the executor's aim point minus the object's origin
    normal: np.ndarray  # (R, 3)
    motion: np.ndarray  # (R, 3) in [-1, 1]
    keypoints: np.ndarray  # (R, 8, 3) box keypoints now minus the origin (R0 c)
    physics: np.ndarray  # (R, 5)
    goal_rotation: np.ndarray  # (R, 3, 3) R_goal R0^T, as the observation's goal
    goal_position: np.ndarray  # (R, 3) the goal's position minus the object's
    tokens: np.ndarray  # (R, D) the location's token


def push_frames(motion: np.ndarray) -> np.ndarray:
    """(R, 3, 3) world -> push frame: the motion's heading turned to +x about the vertical."""
    angle = -np.arctan2(motion[:, 1], motion[:, 0])
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros((len(angle), 3, 3))
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1], out[:, 2, 2] = c, -s, s, c, 1.0
    return out


def turn(frames: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Vectors `v` (R, ..., 3) turned by each row's frame (R, 3, 3)."""
    return np.einsum("rij,r...j->r...i", frames, v)


def box_contact_features(c: Candidates) -> torch.Tensor:
    """(R, 13 + physics) object-relative features of every candidate, so that what is learned
    of a box's proportions carries to other objects (an outcome model's inputs with input_kind
    "box_contact"). In the push's frame: the aim point's height over the
    box's bottom as a fraction of the box's height; the box's height, length and width
    (decimetres); its height over its length; the aim point's offset from the box's centre
    along and across the push in half-lengths; the surface normal; the motion's horizontal
    length and its vertical part; how far the motion goes into the surface (minus its dot
    product with the normal); and the episode's physics."""
    frames = push_frames(c.motion)
    corners, aim = turn(frames, c.keypoints), turn(frames, c.aim)
    normal, motion = turn(frames, c.normal), turn(frames, c.motion)
    low, high = corners.min(1), corners.max(1)
    size, centre = high - low, (high + low) / 2
    length, width, height = size[:, 0], size[:, 1], size[:, 2]
    features = [(aim[:, 2] - low[:, 2]) / height, height * SCALE, length * SCALE,
                width * SCALE, height / length, (aim[:, 0] - centre[:, 0]) / (length / 2),
                (aim[:, 1] - centre[:, 1]) / (width / 2), *normal.T,
                np.linalg.norm(motion[:, :2], axis=1), motion[:, 2],
                -(c.motion * c.normal).sum(1)]
    return torch.as_tensor(np.concatenate([np.stack(features, 1), c.physics], 1),
                           dtype=torch.float32)


def model_inputs(c: Candidates, tokens: bool, kind: str = "raw"
                 ) -> tuple[torch.Tensor, torch.Tensor, np.ndarray]:
    """(inputs (R, F), keypoints now (R, 8, 3), push frames (R, 3, 3)): push frame, decimetres.
    `kind` (INPUT_KINDS): "raw", the aim, normal, motion and box keypoints themselves, or
    "box_contact", box_contact_features (item 40: they carry to unseen objects better)."""
    if kind not in INPUT_KINDS:
        raise ValueError(f"outcome model input kind must be one of {', '.join(INPUT_KINDS)}, "
                         f"got {kind!r}")
    frames = push_frames(c.motion)
    if kind == "box_contact":
        parts = [box_contact_features(c).numpy().astype(np.float64)]
    else:
        parts = [turn(frames, c.aim) * SCALE, turn(frames, c.normal), turn(frames, c.motion),
                 turn(frames, c.keypoints).reshape(len(frames), -1) * SCALE, c.physics]
    if tokens:
        parts.append(c.tokens)
    x = torch.as_tensor(np.concatenate(parts, 1), dtype=torch.float32)
    return x, torch.as_tensor(turn(frames, c.keypoints) * SCALE, dtype=torch.float32), frames


def rotation_matrices(w: torch.Tensor) -> torch.Tensor:
    """(R, 3, 3) rotations of rotation vectors `w` (R, 3) (Rodrigues' formula)."""
    angle = torch.sqrt((w ** 2).sum(-1) + 1e-12)[:, None, None]
    K = torch.zeros(len(w), 3, 3, dtype=w.dtype)
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    K = K - K.transpose(1, 2)
    return torch.eye(3, dtype=w.dtype) + torch.sin(angle) / angle * K + \
        (1 - torch.cos(angle)) / angle ** 2 * K @ K


class OutcomeModel(nn.Module):
    """Inputs -> the object's displacement and rotation vector, in the push's frame."""

    def __init__(self, inputs: int, hidden: int = 256):
        super().__init__()
        self.net = nn.Sequential(nn.Linear(inputs, hidden), nn.LayerNorm(hidden), nn.ReLU(),
                                 nn.Linear(hidden, hidden), nn.LayerNorm(hidden), nn.ReLU(),
                                 nn.Linear(hidden, 6))
        nn.init.zeros_(self.net[-1].weight)  # starts as "the object does not move"
        nn.init.zeros_(self.net[-1].bias)

    def forward(self, x: torch.Tensor, now: torch.Tensor):
        """(keypoints after (R, 8, 3), displacement (R, 3, height 0), rotation vector (R, 3)):
        after = exp(rotation) now + displacement, push frame, decimetres."""
        out = self.net(x)
        displacement = out[:, :3] * torch.tensor([1.0, 1.0, 0.0])  # the reward drops the height
        rotation = out[:, 3:]
        return now @ rotation_matrices(rotation).transpose(1, 2) + displacement[:, None], \
            displacement, rotation


def predicted_rewards(c: Candidates, frames: np.ndarray, prediction, task,
                      progress_reward: float) -> np.ndarray:
    """The env's reward of each predicted outcome: progress_reward x how much it closes the mean
    keypoint distance to the goal, plus the task's success reward where the predicted pose is
    within the task's tolerances (the object assumed still). All relative to the object's
    planar origin now: the goal's keypoints are G (R0 c) plus its planar position."""
    after, displacement, rotation = (t.detach().numpy().astype(np.float64) for t in prediction)
    to_world = frames.transpose(0, 2, 1)
    goal_points = np.einsum("rij,rkj->rki", c.goal_rotation, c.keypoints) + \
        (c.goal_position * PLANAR)[:, None]
    after = turn(to_world, after / SCALE)
    closed = np.linalg.norm(c.keypoints - goal_points, axis=2).mean(1) - \
        np.linalg.norm(after - goal_points, axis=2).mean(1)
    moved = turn(to_world, displacement / SCALE)
    planar = np.hypot(*(c.goal_position[:, :2] - moved[:, :2]).T)
    turned = to_world @ rotation_matrices(torch.as_tensor(rotation)).numpy() @ frames
    # The rotation left to the goal: G turned^T; its angle from its trace.
    cos = (np.einsum("rij,rij->r", c.goal_rotation, turned) - 1.0) / 2.0
    success = planar <= task.success_position
    if task.check_orientation:
        success &= np.arccos(np.clip(cos, -1.0, 1.0)) <= task.success_orientation
    return progress_reward * closed + task.success_reward * success


# --- the collected data ------------------------------------------------------------------------
def _rotations(quaternions: np.ndarray) -> np.ndarray:
    return np.stack([quat_wxyz_to_matrix(q) for q in quaternions])


def data_candidates(data: dict) -> Candidates:
    """Every collected candidate (row) as Candidates."""
    state, location = data["state"], data["location"]
    R0 = _rotations(data["outcome_pose"][:, 3:])
    p0 = data["outcome_pose"][:, :3]
    goal_R = _rotations(data["outcome_goal"][:, 3:])
    return Candidates(
        aim=data["outcome_aims"][state, location] - p0[state],
        normal=data["features_local"][state, location, 6:9].astype(np.float64),
        motion=data["motion"].astype(np.float64),
        keypoints=np.einsum("sij,skj->ski", R0, data["outcome_corners"])[state],
        physics=data["outcome_physics"][state],
        goal_rotation=(goal_R @ R0.transpose(0, 2, 1))[state],
        goal_position=(data["outcome_goal"][:, :3] - p0)[state],
        tokens=data["features_tokens"][state, location])


def data_after(data: dict, frames: np.ndarray) -> torch.Tensor:
    """Where each row's primitive left the keypoints (push frame, decimetres, relative to the
    planar origin before): the model's target."""
    state = data["state"]
    p0 = data["outcome_pose"][state, :3]
    after = np.einsum("rij,rkj->rki", _rotations(data["pose_after"][:, 3:]),
                      data["outcome_corners"][state]) + \
        ((data["pose_after"][:, :3] - p0) * PLANAR)[:, None]
    return torch.as_tensor(turn(frames, after) * SCALE, dtype=torch.float32)


def fit_model(data: dict, tokens: bool, updates: int, seed: int,
              history: list | None = None, kind: str = "raw") -> OutcomeModel:
    """A model fitted to every row of `data` (Huber loss on the keypoints after, `updates`
    Adam steps of BATCH_ROWS rows) on model_inputs of `kind`, in eval mode; `history` as
    fit_network's."""
    missing = [k for k in OUTCOME_KEYS + OUTCOME_ROW_KEYS if k not in data]
    if missing:
        raise ValueError(f"outcome data without {', '.join(missing)} (collected before "
                         "outcomes were stored)")
    x, now, frames = model_inputs(data_candidates(data), tokens, kind)
    return fit_network(x, now, data_after(data, frames), updates, seed, history)


def fit_network(x: torch.Tensor, now: torch.Tensor, target: torch.Tensor, updates: int,
                seed: int, history: list | None = None) -> OutcomeModel:
    """An OutcomeModel on inputs `x` (R, F) fitted to keypoints after `target` (R, 8, 3) from
    keypoints now `now` (fit_model's loss and steps; studies of other inputs call it). Given a
    list `history`, appends the fit's learning curve to it: every HISTORY_EVERY updates (and at
    the last) {"update", "huber_loss"}, the mean loss of the batches since the previous row.
    Recording draws no random numbers: the weights are those of a fit without it."""
    torch.manual_seed(seed)
    model = OutcomeModel(x.shape[1])
    optimiser = torch.optim.Adam(model.parameters(), lr=3e-4)
    done, window = 0, []
    while done < updates:
        for batch in torch.randperm(len(x)).split(BATCH_ROWS):
            loss = nn.functional.huber_loss(model(x[batch], now[batch])[0], target[batch],
                                            delta=0.5)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            done += 1
            if history is not None:
                window.append(loss.item())
                if done % HISTORY_EVERY == 0 or done == updates:
                    history.append({"update": done, "huber_loss": sum(window) / len(window)})
                    window = []
            if done == updates:
                break
    return model.eval()
