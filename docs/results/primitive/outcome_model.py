"""Choosing primitives by a model of what they do to the object: README.md's item 35.

    # held-out objects: the outcome model's choices against the rank-fitted critic's
    .venv/bin/python docs/results/primitive/outcome_model.py study \
        models/weights/push_turn_primitive --data runs/outcome_data2 \
        --out docs/results/primitive/outcome_model_study.json
    # the model fitted to every state, then the policy that chooses by it on the 200 episodes
    .venv/bin/python docs/results/primitive/outcome_model.py fit \
        models/weights/push_turn_primitive --data runs/outcome_data2 \
        --out docs/results/primitive/outcome_model.pt
    .venv/bin/python docs/results/primitive/outcome_model.py evaluate \
        docs/results/primitive/outcome_model.pt \
        --run models/weights/push_turn_primitive --set primitive.success_at_rest=true \
        --objects data/library --split unseen --episodes 200 --record 0 \
        --report docs/results/primitive/eval_push_turn_outcome_model_at_rest.json

Why: the distilled critic (item 34) must learn a primitive's reward for one goal, but the reward
is a known function of where the primitive leaves the object: progress_reward x how much it
closes the mean distance between the object's box keypoints and the goal's, plus the success
reward. So the model here predicts only the object's motion, which does not depend on the goal:
from the aim point (relative to the object's origin), the surface normal, the push motion, the
object's box keypoints at its current pose, the episode's physics (mass, frictions,
restitution) and, with --tokens, the location's contact token, the object's displacement and
rotation (6 numbers), so its keypoints after; the predicted reward follows by the env's own rule
(a predicted success assumes the object still). Inputs and outputs are in the push's frame (the
motion's heading turned to +x), so a push and the same push turned about the vertical are one
example.

`study`: each split holds out `--holdout-objects` objects whole; the held-out states' choices
are scored in the rewards the simulator measured (rl/lookahead_distill.scores_quality), against
the run's critic before and after the rank fit of item 34 on the same states and updates.
`evaluate`: `corn-drake evaluate` with the run's agent choosing, among its actor's motion and a
fixed bank of `BANK` uniform motions at every usable location, the candidate of highest
predicted reward (PrimitiveAgent.choose replaced in this process; the actor and critic are the
run's, the critic unused). Data: `lookahead_distill.py collect` folders whose states hold their
outcomes. Reports are written atomically.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import torch
from torch import nn

sys.path.insert(0, str(Path(__file__).resolve().parent))
from distill_scaling import (BATCH_ROWS, held_out_objects, load_study_data,  # noqa: E402
                             select_states, study_arguments)

from corn_drake.rl.lookahead_distill import choice_quality, fit_critic, scores_quality  # noqa: E402
from corn_drake.rl.primitive_agent import load_primitive_run  # noqa: E402
from corn_drake.storage.atomic_files import write_json  # noqa: E402
from corn_drake.transforms import from_pose9, quat_wxyz_to_matrix  # noqa: E402

SCALE = 10.0  # metres -> decimetres, as the policy's features
PLANAR = np.array([1.0, 1.0, 0.0])  # the reward's keypoints drop the origin's height
OUTCOME_KEYS = ("outcome_pose", "outcome_goal", "outcome_corners", "outcome_aims",
                "outcome_physics")
OUTCOME_ROW_KEYS = ("pose_after", "still_after", "success_after")
BANK = 32  # uniform motions tried at every location when choosing (besides the actor's)


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


def _rotations(quaternions: np.ndarray) -> np.ndarray:
    return np.stack([quat_wxyz_to_matrix(q) for q in quaternions])


def push_frames(motion: np.ndarray) -> np.ndarray:
    """(R, 3, 3) world -> push frame: the motion's heading turned to +x about the vertical."""
    angle = -np.arctan2(motion[:, 1], motion[:, 0])
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros((len(angle), 3, 3))
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1], out[:, 2, 2] = c, -s, s, c, 1.0
    return out


def _turn(frames: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("rij,r...j->r...i", frames, v)


def model_inputs(c: Candidates, tokens: bool) -> tuple[torch.Tensor, torch.Tensor, np.ndarray]:
    """(inputs (R, F), keypoints now (R, 8, 3), push frames (R, 3, 3)): push frame, decimetres."""
    frames = push_frames(c.motion)
    parts = [_turn(frames, c.aim) * SCALE, _turn(frames, c.normal), _turn(frames, c.motion),
             _turn(frames, c.keypoints).reshape(len(frames), -1) * SCALE, c.physics]
    if tokens:
        parts.append(c.tokens)
    x = torch.as_tensor(np.concatenate(parts, 1), dtype=torch.float32)
    return x, torch.as_tensor(_turn(frames, c.keypoints) * SCALE, dtype=torch.float32), frames


def _rodrigues(w: torch.Tensor) -> torch.Tensor:
    """(R, 3, 3) rotations of rotation vectors `w` (R, 3)."""
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
        return now @ _rodrigues(rotation).transpose(1, 2) + displacement[:, None], \
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
    after = _turn(to_world, after / SCALE)
    closed = np.linalg.norm(c.keypoints - goal_points, axis=2).mean(1) - \
        np.linalg.norm(after - goal_points, axis=2).mean(1)
    moved = _turn(to_world, displacement / SCALE)
    planar = np.hypot(*(c.goal_position[:, :2] - moved[:, :2]).T)
    turned = to_world @ _rodrigues(torch.as_tensor(rotation)).numpy() @ frames  # R_after R0^T
    # The rotation left to the goal: G turned^T; its angle from its trace.
    cos = (np.einsum("rij,rij->r", c.goal_rotation, turned) - 1.0) / 2.0
    success = planar <= task.success_position
    if task.check_orientation:
        success &= np.arccos(np.clip(cos, -1.0, 1.0)) <= task.success_orientation
    return progress_reward * closed + task.success_reward * success


# --- the collected data ------------------------------------------------------------------------
def data_candidates(data: dict) -> Candidates:
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
    return torch.as_tensor(_turn(frames, after) * SCALE, dtype=torch.float32)


def fit_model(data: dict, tokens: bool, updates: int, seed: int) -> OutcomeModel:
    torch.manual_seed(seed)
    x, now, frames = model_inputs(data_candidates(data), tokens)
    target = data_after(data, frames)
    model = OutcomeModel(x.shape[1])
    optimiser = torch.optim.Adam(model.parameters(), lr=3e-4)
    done = 0
    while done < updates:
        for batch in torch.randperm(len(x)).split(BATCH_ROWS):
            loss = nn.functional.huber_loss(model(x[batch], now[batch])[0], target[batch],
                                            delta=0.5)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            done += 1
            if done == updates:
                break
    return model.eval()


def model_quality(model: OutcomeModel, data: dict, tokens: bool, task,
                  progress_reward: float) -> dict:
    """The model's mean keypoint error (m) against "the object does not move"'s, and what its
    choices earned (scores_quality's `chosen`, in the rewards the simulator measured)."""
    candidates = data_candidates(data)
    x, now, frames = model_inputs(candidates, tokens)
    with torch.no_grad():
        prediction = model(x, now)
    truth = data_after(data, frames).numpy()
    error = np.linalg.norm(prediction[0].numpy() - truth, axis=2).mean() / SCALE
    still = np.linalg.norm(now.numpy() - truth, axis=2).mean() / SCALE
    scores = predicted_rewards(candidates, frames, prediction, task, progress_reward)
    return {"keypoint_error_m": float(error), "no_motion_error_m": float(still),
            "chosen": scores_quality(scores, data)["chosen"]}


def study(args) -> None:
    data, objects = load_study_data(args.data, args.holdout_objects,
                                    OUTCOME_KEYS + OUTCOME_ROW_KEYS)
    base, _, _ = load_primitive_run(args.run)
    task, progress = base.env.task, base.primitive.progress_reward
    report = {"run": args.run, "data": [str(d) for d in args.data],
              "states": int(len(data["features_tokens"])), "objects": len(objects),
              "holdout_objects": args.holdout_objects, "updates": args.updates, "splits": []}
    for split in range(args.splits):
        held, _ = held_out_objects(objects, args.holdout_objects, split)
        inside = np.isin(data["object"], held)
        held_out = select_states(data, np.flatnonzero(inside))
        train = select_states(data, np.flatnonzero(~inside))
        row = {"split": split, "train_states": int(len(train["features_tokens"])),
               "held_out_states": int(len(held_out["features_tokens"]))}
        _, critic_agent, _ = load_primitive_run(args.run)
        row["shipped_critic"] = choice_quality(critic_agent, held_out)
        epochs = max(1, round(args.updates / math.ceil(len(train["reward"]) / BATCH_ROWS)))
        fit_critic(critic_agent, train, epochs, batch_size=BATCH_ROWS, loss="rank", seed=split)
        row["rank_critic"] = choice_quality(critic_agent, held_out)
        for tokens in (False, True):
            model = fit_model(train, tokens, args.updates, split)
            row["outcome_model" + ("_tokens" if tokens else "")] = {
                "held_out": model_quality(model, held_out, tokens, task, progress),
                "train": model_quality(model, train, tokens, task, progress)}
        report["splits"].append(row)
        write_json(args.out, report)
        print(f"split {split}: best {row['shipped_critic']['best']:.3f}, shipped critic "
              f"{row['shipped_critic']['chosen']:.3f}, rank critic "
              f"{row['rank_critic']['chosen']:.3f}, outcome model "
              f"{row['outcome_model']['held_out']['chosen']:.3f} (tokens "
              f"{row['outcome_model_tokens']['held_out']['chosen']:.3f}); keypoint error "
              f"{row['outcome_model']['held_out']['keypoint_error_m']:.4f} m against "
              f"{row['outcome_model']['held_out']['no_motion_error_m']:.4f} for no motion",
              flush=True)


def fit(args) -> None:
    from corn_drake.storage.checkpoint_files import save_checkpoint

    data, _ = load_study_data(args.data, 0, OUTCOME_KEYS + OUTCOME_ROW_KEYS)
    model = fit_model(data, args.tokens, args.updates, 0)
    save_checkpoint(args.out, {"model": model.state_dict(),
                               "inputs": int(model.net[0].in_features),
                               "tokens": bool(args.tokens),
                               "states": int(len(data["features_tokens"])),
                               "data": [str(d) for d in args.data], "updates": args.updates})
    print(f"wrote {args.out}: fitted to {len(data['features_tokens'])} states, "
          f"{len(data['reward'])} candidates")


# --- the policy that chooses by the model -------------------------------------------------------
def obs_candidates(agent, obs: dict, bank: np.ndarray):
    """(Candidates, [(location, cloud point, motion)], which locations are usable (L,), every
    location's cloud point (L,)) for one observation: the actor's motion and every bank motion
    at every usable location."""
    from corn_drake.systems.low_push import push_contact

    features, points = agent.features(obs)
    with torch.no_grad():
        actor = agent.actor(features)[0].numpy().astype(np.float64)
    usable = features["mask"][0].numpy() > 0.5
    p = np.asarray(obs["object_position"], np.float64)
    keypoints = np.asarray(obs["object_keypoints"], np.float64).reshape(-1, 3) - p
    goal_position, goal_rotation = from_pose9(np.asarray(obs["goal"], np.float64))
    rows = []
    # No usable location (every pre-contact point under the table): all of them, as the agent's
    # own choice then falls back to its argmax over all-masked scores.
    for location in np.flatnonzero(usable) if usable.any() else range(len(usable)):
        point = int(points[0, location])
        aim = push_contact(obs["cloud"], obs["normals"], point, agent.primitive_config)[0] - p
        normal = np.asarray(obs["normals"][point], np.float64)
        for motion in np.vstack([actor[location][None], bank]):
            rows.append((int(location), point, motion, aim, normal))
    n = len(rows)
    candidates = Candidates(
        aim=np.stack([r[3] for r in rows]), normal=np.stack([r[4] for r in rows]),
        motion=np.stack([r[2] for r in rows]), keypoints=np.repeat(keypoints[None], n, 0),
        physics=np.repeat(np.asarray(obs["physics"], np.float64)[None], n, 0),
        goal_rotation=np.repeat(goal_rotation[None], n, 0),
        goal_position=np.repeat(goal_position[None], n, 0),
        tokens=features["tokens"][0].numpy()[[r[0] for r in rows]])
    return candidates, [(r[0], r[1], r[2]) for r in rows], usable, points[0].numpy()


def evaluate(args, rest: list[str]) -> int:
    from corn_drake.cli import main as cli
    from corn_drake.rl import primitive_agent
    from corn_drake.storage.checkpoint_files import load_checkpoint

    if "--run" not in rest[:-1]:
        raise SystemExit("outcome_model.py evaluate MODEL --run RUN ...: --run names the "
                         "primitive run whose actor proposes motions")
    saved = load_checkpoint(args.model)
    model = OutcomeModel(saved["inputs"])
    model.load_state_dict(saved["model"])
    model.eval()
    tokens = saved["tokens"]
    bank = np.random.default_rng(0).uniform(-1.0, 1.0, (BANK, 3))
    run_cfg = evaluated_config(rest)  # the evaluated task's tolerances score the candidates

    def choose(self, obs):
        """PrimitiveAgent.choose's answer, chosen by the outcome model's predicted reward."""
        candidates, options, usable, points = obs_candidates(self, obs, bank)
        x, now, frames = model_inputs(candidates, tokens)
        with torch.no_grad():
            prediction = model(x, now)
        scores = predicted_rewards(candidates, frames, prediction, run_cfg.env.task,
                                   run_cfg.primitive.progress_reward)
        best = int(np.argmax(scores))
        location, point, motion = options[best]
        per_location = np.full(len(usable), -np.inf)
        motions = np.zeros((len(usable), 3))
        for (loc, _, m), score in zip(options, scores):
            if score > per_location[loc]:
                per_location[loc], motions[loc] = score, m
        shown = np.where(np.isfinite(per_location), per_location,
                         per_location[np.isfinite(per_location)].min())
        return {"point": point, "motion": np.asarray(motion, np.float64), "location": location,
                "scores": shown, "usable": usable, "candidates": points, "motions": motions}

    primitive_agent.PrimitiveAgent.choose = choose
    code = cli(["evaluate", *rest])
    if code == 0 and "--report" in rest[:-1]:
        annotate_report(Path(rest[rest.index("--report") + 1]), args.model, saved)
    return code


def evaluated_config(rest: list[str]):
    """The primitive run's config as `corn-drake evaluate` will run it: its --task overlay and
    its --set overrides applied as evaluate applies them, so the predicted success uses the
    evaluated task's tolerances and reward."""
    import argparse

    from corn_drake.commands.evaluate import with_primitive_task
    from corn_drake.config.overrides import apply_sets

    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--run", required=True)
    parser.add_argument("--task", default=None)
    parser.add_argument("--set", action="append", default=[], dest="set")
    known, _ = parser.parse_known_args(rest)
    base, _, _ = load_primitive_run(known.run)
    if known.task is not None:
        base = with_primitive_task(base, known.task)
    return apply_sets(base, known.set, only=("env", "primitive"))


def annotate_report(report: Path, model_path: Path, saved: dict) -> None:
    """Names the model that chose in an evaluate report (the report's `run` is the run whose
    actor proposed the motions)."""
    import json

    content = json.loads(report.read_text())
    content["outcome_model"] = {"file": str(model_path), "states": saved["states"],
                                "updates": saved["updates"], "tokens": saved["tokens"],
                                "data": saved["data"], "bank_motions": BANK}
    write_json(report, content)


def main() -> None:
    command = sys.argv[1] if len(sys.argv) > 1 else ""
    torch.set_num_threads(1)
    if command == "study":
        parser = study_arguments(__doc__.splitlines()[0])
        study(parser.parse_args(sys.argv[2:]))
    elif command == "fit":
        import argparse

        parser = argparse.ArgumentParser(description="the outcome model fitted to every state")
        parser.add_argument("run")
        parser.add_argument("--data", type=Path, nargs="+", required=True)
        parser.add_argument("--updates", type=int, default=2000)
        parser.add_argument("--tokens", action="store_true")
        parser.add_argument("--out", type=Path, required=True)
        fit(parser.parse_args(sys.argv[2:]))
    elif command == "evaluate":
        import argparse

        parser = argparse.ArgumentParser(description="corn-drake evaluate, choosing by the model")
        parser.add_argument("model", type=Path)
        args, rest = parser.parse_known_args(sys.argv[2:])
        sys.exit(evaluate(args, rest))
    else:
        raise SystemExit("usage: outcome_model.py study|fit|evaluate ... (see the docstring)")


if __name__ == "__main__":
    main()
