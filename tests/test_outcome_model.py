"""The outcome model (rl/primitive/outcome/model.py) and the choice made by it (rl/primitive/outcome/chooser.py): the
reward it predicts for a known outcome is the env's own rule's, a fit learns a push's effect, the
chooser's push frames come back to the world (a model that says "every push carries the object
along it" pushes toward the goal), and bad model files are refused by name."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from corn_drake.config.plumbing.diagram_files import load_primitive_env_config
from corn_drake.errors import InputError, MissingInputError
from corn_drake.rl.primitive.outcome.model_file import load_outcome_parts, save_outcome_model
from corn_drake.rl.primitive.outcome.model import (SCALE, Candidates, OutcomeModel, data_after,
                                         data_candidates, fit_model, model_inputs,
                                         predicted_rewards)
from corn_drake.systems.reward import keypoints_at, pose_errors, within_tolerance
from corn_drake.transforms import pose9

CORNERS = np.array([[x, y, z] for x in (-0.05, 0.05) for y in (-0.03, 0.03)
                    for z in (-0.02, 0.02)])
INPUTS = 38  # model_inputs without tokens: aim, normal, motion (9), 8 keypoints (24), physics (5)


def _random_rotation(rng, tilt: float) -> np.ndarray:
    """A yaw anywhere and a tilt of up to `tilt` rad about a horizontal axis."""
    def about(axis, angle):
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    h = rng.uniform(0, 2 * np.pi)
    return about(np.array([0.0, 0.0, 1.0]), rng.uniform(-np.pi, np.pi)) @ \
        about(np.array([np.cos(h), np.sin(h), 0.0]), rng.uniform(0, tilt))


def _rotation_vector(R: np.ndarray) -> np.ndarray:
    angle = np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))
    if angle < 1e-9:
        return np.zeros(3)
    return angle / (2 * np.sin(angle)) * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0],
                                                   R[1, 0] - R[0, 1]])


def _model_saying(displacement_push: np.ndarray, rotation_push: np.ndarray) -> OutcomeModel:
    """A model whose every prediction is this displacement and rotation (push frame, metres)."""
    model = OutcomeModel(INPUTS)
    with torch.no_grad():
        model.net[-1].bias.copy_(torch.as_tensor(
            np.concatenate([displacement_push * SCALE, rotation_push]), dtype=torch.float32))
    return model.eval()


@pytest.mark.parametrize("case", range(6))
def test_the_predicted_reward_of_a_known_outcome_is_the_envs_rule(case):
    """A primitive that moves the object from (p0, R0) to (p1, R1): the reward predicted from
    that exact motion equals progress x the closed keypoint distance plus the success reward,
    both computed by systems/reward's own functions in the world frame."""
    rng = np.random.default_rng(case)
    task = load_primitive_env_config("full6d" if case % 2 else "push_turn").task
    progress = 10.0
    p0 = np.array([*rng.uniform(-0.1, 0.1, 2), 0.43])
    R0 = _random_rotation(rng, 0.6)
    turn = _random_rotation(rng, 0.3)
    R1, p1 = turn @ R0, p0 + np.array([*rng.uniform(-0.06, 0.06, 2), rng.uniform(-0.02, 0.02)])
    # Cases 0-1: the goal is where the primitive leaves the object (a success); others: elsewhere.
    near = case < 2
    Rg = R1 if near else _random_rotation(rng, 0.6)
    pg = p1 + (np.array([0.01, -0.01, 0.0]) if near else np.array([*rng.uniform(-0.2, 0.2, 2),
                                                                     0.0]))
    motion = rng.uniform(-1, 1, (1, 3))
    from corn_drake.rl.primitive.outcome.model import push_frames

    F = push_frames(motion)[0]
    d_world = (p1 - p0) * np.array([1.0, 1.0, 0.0])
    model = _model_saying(F @ d_world, F @ _rotation_vector(turn))
    c = Candidates(aim=np.zeros((1, 3)), normal=np.array([[1.0, 0, 0]]), motion=motion,
                   keypoints=(CORNERS @ R0.T)[None], physics=np.ones((1, 5)),
                   goal_rotation=(Rg @ R0.T)[None], goal_position=(pg - p0)[None],
                   tokens=np.zeros((1, 4)))
    x, now, frames = model_inputs(c, tokens=False)
    with torch.no_grad():
        predicted = predicted_rewards(c, frames, model(x, now), task, progress)[0]
    goal_points = keypoints_at(CORNERS, pg, Rg)
    before = np.linalg.norm(keypoints_at(CORNERS, p0, R0) - goal_points, axis=1).mean()
    after = np.linalg.norm(keypoints_at(CORNERS, p1, R1) - goal_points, axis=1).mean()
    success = within_tolerance(task, *pose_errors(p1, R1, pg, Rg))
    assert success == near
    assert predicted == pytest.approx(progress * (before - after) + task.success_reward * success,
                                      abs=2e-5)


def _synthetic_data(states: int, rng) -> dict:
    """Collected-data arrays (rl/primitive/outcome/collect.stack_states' layout) of a world where every push moves
    the object half the push's planar length along its heading and never turns it."""
    per = 12
    quats = np.tile([1.0, 0, 0, 0], (states, 1))
    pose = np.concatenate([np.c_[rng.uniform(-0.1, 0.1, (states, 2)), np.full(states, 0.43)],
                           quats], 1)
    goal = pose.copy()
    goal[:, :2] += 0.1
    state = np.repeat(np.arange(states), per)
    location = rng.integers(0, 16, len(state))
    motion = rng.uniform(-1, 1, (len(state), 3)).astype(np.float32)
    after = pose[state].copy()
    after[:, :2] += 0.5 * 0.15 * motion[:, :2]
    local = np.zeros((states, 16, 9), np.float32)
    local[..., 6] = 1.0
    return {"state": state, "location": location, "motion": motion,
            "reward": np.zeros(len(state), np.float32),
            "features_tokens": np.zeros((states, 16, 4), np.float32),
            "features_local": local, "outcome_pose": pose, "outcome_goal": goal,
            "outcome_corners": np.repeat(CORNERS[None], states, 0),
            "outcome_aims": np.repeat(pose[:, None, :3], 16, 1),
            "outcome_physics": np.ones((states, 5)),
            "pose_after": after, "still_after": np.ones(len(state), bool),
            "success_after": np.zeros(len(state), bool)}


def test_a_fit_learns_how_far_a_push_carries_the_object():
    rng = np.random.default_rng(0)
    data = _synthetic_data(64, rng)
    model = fit_model(data, tokens=False, updates=600, seed=0)
    x, now, frames = model_inputs(data_candidates(data), tokens=False)
    truth = data_after(data, frames)
    with torch.no_grad():
        predicted = model(x, now)[0]
    error = (predicted - truth).norm(dim=2).mean()
    still = (now - truth).norm(dim=2).mean()
    assert error < 0.25 * still, (float(error), float(still))
    with pytest.raises(ValueError, match="pose_after"):
        fit_model({k: v for k, v in data.items() if k != "pose_after"}, False, 1, 0)


def test_a_fit_records_its_learning_curve_without_changing_its_weights():
    """The history a shipped outcome folder's training_history.json holds: a row every
    HISTORY_EVERY updates and one at the last, the loss falling on data it can learn, and the
    weights bit for bit those of a fit that records nothing (the shipped model refits exactly)."""
    from corn_drake.rl.primitive.outcome.model import HISTORY_EVERY

    data = _synthetic_data(32, np.random.default_rng(1))
    updates = 2 * HISTORY_EVERY + 30
    history = []
    recorded = fit_model(data, False, updates, seed=3, history=history)
    plain = fit_model(data, False, updates, seed=3)
    assert [row["update"] for row in history] == [HISTORY_EVERY, 2 * HISTORY_EVERY, updates]
    assert history[-1]["huber_loss"] < 0.5 * history[0]["huber_loss"], history
    for key, value in plain.state_dict().items():
        assert torch.equal(value, recorded.state_dict()[key]), key


def test_a_model_of_pushes_that_carry_the_object_pushes_toward_the_goal():
    """The chooser's push frames back in the world: told that every push carries the object
    5 cm along its own heading, it chooses a motion heading for the goal (5 cm away in +y)."""
    from corn_drake.nn.encoders.encoder_files import make_policy_encoder
    from corn_drake.rl.primitive.outcome.chooser import OutcomeChooser
    from corn_drake.rl.primitive.agent import PrimitiveAgent
    from corn_drake.rl.envs.primitive_env import PrimitiveEnv

    torch.manual_seed(0)
    agent = PrimitiveAgent(make_policy_encoder("corn")).eval()
    cfg = load_primitive_env_config("push")
    env = PrimitiveEnv(cfg, agent=agent)
    obs, _ = env.reset(seed=1)
    # The observation's goal is relative to the object: the position difference and
    # R_goal R^T (systems/observations.py), here 5 cm along +y, unturned.
    obs = {**obs, "goal": pose9(np.array([0.0, 0.05, 0.0]), np.eye(3)).astype(np.float32)}
    agent.outcome_chooser = OutcomeChooser(_model_saying(np.array([0.05, 0, 0]), np.zeros(3)),
                                           tokens=False)
    agent.task = cfg.task
    choice = agent.choose(obs)
    heading = choice["motion"][:2] / np.linalg.norm(choice["motion"][:2])
    assert heading @ np.array([0.0, 1.0]) > 0.9, choice["motion"]
    # Its scores: each location's best candidate; the chosen location's is the highest.
    assert choice["scores"][choice["location"]] == pytest.approx(choice["scores"].max())
    assert choice["point"] == choice["candidates"][choice["location"]]


def test_bad_model_files_are_refused_by_name(tmp_path):
    missing = tmp_path / "outcome_model.pt"
    with pytest.raises(MissingInputError, match="outcome_model.pt"):
        load_outcome_parts(missing)
    missing.write_bytes(b"not a checkpoint")
    with pytest.raises(InputError, match="outcome_model.pt"):
        load_outcome_parts(missing)
    wrong = tmp_path / "wrong.pt"
    model = OutcomeModel(INPUTS)
    save_outcome_model(wrong, model, tokens=False, states=3)
    facts = load_outcome_parts(wrong).facts
    assert facts["states"] == 3 and facts["inputs"] == INPUTS and facts["tokens"] is False
    state = torch.load(wrong, weights_only=False)
    state["inputs"] = INPUTS + 1
    torch.save(state, wrong)
    with pytest.raises(InputError, match="wrong.pt.*do not fit"):
        load_outcome_parts(wrong)


def test_a_model_of_object_relative_inputs_learns_pushes_and_its_file_says_what_it_reads(
        tmp_path):
    """input_kind "box_contact" (item 40): the model reads box_contact_features, learns the
    synthetic world's pushes from them, its file records the kind and the chooser feeds it the
    same features (its scores are the model's own predicted rewards); an unknown kind is refused
    by name, and a file from before kinds were recorded reads as "raw"."""
    from corn_drake.rl.primitive.outcome.chooser import OutcomeChooser
    from corn_drake.rl.primitive.outcome.model import INPUT_KINDS, box_contact_features

    data = _synthetic_data(64, np.random.default_rng(2))
    model = fit_model(data, tokens=False, updates=600, seed=0, kind="box_contact")
    c = data_candidates(data)
    x, now, frames = model_inputs(c, tokens=False, kind="box_contact")
    assert model.net[0].in_features == box_contact_features(c).shape[1] == 18
    torch.testing.assert_close(x, box_contact_features(c))
    truth = data_after(data, frames)
    with torch.no_grad():
        predicted = model(x, now)
    error = (predicted[0] - truth).norm(dim=2).mean()
    still = (now - truth).norm(dim=2).mean()
    assert error < 0.25 * still, (float(error), float(still))

    path = tmp_path / "box.pt"
    save_outcome_model(path, model, tokens=False, input_kind="box_contact", states=64)
    parts = load_outcome_parts(path)
    assert parts.facts["input_kind"] == "box_contact"
    chooser = OutcomeChooser(parts.model, False, parts.facts)
    task = load_primitive_env_config("push_turn").task
    np.testing.assert_allclose(chooser.scores(c, task, 10.0),
                               predicted_rewards(c, frames, predicted, task, 10.0), rtol=1e-6)
    with pytest.raises(ValueError, match="input kind must be one of raw, box_contact"):
        model_inputs(c, tokens=False, kind="cloud")
    save_outcome_model(path, model, tokens=False, input_kind="cloud")
    with pytest.raises(InputError, match="box.pt: input_kind must be one of"):
        load_outcome_parts(path)
    old = tmp_path / "old.pt"
    save_outcome_model(old, OutcomeModel(INPUTS), tokens=False)
    assert load_outcome_parts(old).facts["input_kind"] == "raw" == INPUT_KINDS[0]


# --- the chooser's arithmetic, and files from before the retired settings --------------------
class _TableModel(torch.nn.Module):
    """Stands in for an OutcomeModel in the chooser's arithmetic: candidate i's planar
    displacement is row i of a table (push frame, metres), never a turn."""

    def __init__(self, displacements):
        super().__init__()
        self.table = torch.as_tensor(np.asarray(displacements) * SCALE, dtype=torch.float32)

    def forward(self, x, now):
        moved = self.table * torch.tensor([1.0, 1.0, 0.0])
        return now + moved[:, None], moved, torch.zeros(len(moved), 3)


def _pushes_along_x(aim_heights, goal_x: float = 0.3) -> Candidates:
    """Candidates pushing the CORNERS box along +x (their push frame is the world's) from its
    -x face at these heights over its origin, toward a goal goal_x along +x, unturned."""
    n = len(aim_heights)
    return Candidates(aim=np.c_[np.full(n, -0.05), np.zeros(n), aim_heights],
                      normal=np.tile([-1.0, 0.0, 0.0], (n, 1)),
                      motion=np.tile([1.0, 0.0, 0.0], (n, 1)),
                      keypoints=np.repeat(CORNERS[None], n, 0), physics=np.ones((n, 5)),
                      goal_rotation=np.repeat(np.eye(3)[None], n, 0),
                      goal_position=np.tile([goal_x, 0.0, 0.0], (n, 1)),
                      tokens=np.zeros((n, 4)))


def test_the_chooser_scores_each_candidate_by_its_predicted_reward():
    """Candidate 0 carries the box 10 cm toward the goal, candidate 1 3 cm: each one's score is
    its predicted reward (progress x the closed metres), bit for bit, and the first wins."""
    from corn_drake.rl.primitive.outcome.chooser import OutcomeChooser

    task, progress = load_primitive_env_config("push").task, 10.0
    c = _pushes_along_x([0.0, 0.0])
    model = _TableModel([[0.10, 0, 0], [0.03, 0, 0]])
    x, now, frames = model_inputs(c, tokens=False)
    rewards = predicted_rewards(c, frames, model(x, now), task, progress)
    assert rewards == pytest.approx([1.0, 0.3], abs=1e-5)
    scores = OutcomeChooser(model, tokens=False).scores(c, task, progress)
    assert np.array_equal(scores, rewards) and np.argmax(scores) == 0


def test_a_file_written_with_an_ensemble_and_a_tilt_classifier_loads_its_model(tmp_path):
    """Files fitted for the retired outcome.pessimism / tilt_veto / tilt_blend hold further
    members, a tilt classifier and the reward of tilts: reading takes the model and leaves the
    rest out, so such a folder chooses as one without them."""
    torch.manual_seed(0)
    model = OutcomeModel(INPUTS)
    torch.nn.init.normal_(model.net[-1].weight, std=0.1)
    path = tmp_path / "ensemble.pt"
    save_outcome_model(path, model, False, states=5)
    state = torch.load(path, weights_only=False)
    torch.save({**state, "members": [OutcomeModel(INPUTS).state_dict()],
                "tilt": {"mean": torch.zeros(18)}, "tilt_inputs": 18, "tilted_reward": -0.5},
               path)
    parts = load_outcome_parts(path)
    assert parts.facts["states"] == 5
    assert not {"members", "tilt", "tilt_inputs", "tilted_reward"} & set(parts.facts)
    x, now = torch.randn(4, INPUTS), torch.randn(4, 8, 3)
    with torch.no_grad():
        assert torch.equal(parts.model(x, now)[0], model.eval()(x, now)[0])


def test_the_retired_outcome_settings_are_refused_where_evaluate_applies_them():
    from corn_drake.config.plumbing.diagram_files import primitive_run_on
    from corn_drake.config.primitive import PrimitiveTrainConfig

    for retired in ("outcome.pessimism=1", "outcome.tilt_veto=0.5", "outcome.tilt_blend=true"):
        with pytest.raises(InputError, match=r"outcome was retired \(.*0\.345"):
            primitive_run_on(PrimitiveTrainConfig(), None, [retired])
