"""Do physics priors help the outcome chooser on objects it never saw? README.md's item 39.

    .venv/bin/python docs/results/primitive/physics_priors.py \
        models/weights/push_turn_primitive --data runs/big_collect --library data/library_big \
        --out docs/results/primitive/physics_priors.json

Item 38 left the outcome model (rl/primitive/outcome/model.py) no better than "the object does not move"
on held-out objects, and its tilt classifier at ROC AUC 0.78: both see the object only as its
bounding box, which is the same for a lying cylinder (it rolls) and a box (it slides). Two priors
from pushing mechanics, computed from the object's cloud as the privileged observation has it:

  support   per candidate, in the push's direction: how far the object's support (its cloud
            points within 3 / 10 / 20 mm of its lowest) reaches ahead of, behind and beside the
            cloud's centroid; the centroid's and the aim's heights over the lowest point; the
            quasi-static tipping ratios (support ahead / aim height, / centroid height); the
            aim's offset from the centroid. 19 numbers, decimetres.
  analytic  a quasi-static planar push (ellipsoidal limit surface; the object-finger friction
            cone decides sticking or sliding): the finger runs from the pre-contact point along
            the push's horizontal part, the first cloud point within FINGER_RADIUS of its path
            and above its tip is the contact, and the object's planar displacement and yaw are
            integrated over the travel left after contact (times TRAVEL_GAIN: the impedance-
            controlled hand lags its target), with the limit surface's length the support's
            mean distance from the centroid (times SUPPORT_GAIN). No tipping, no learning.

Per split `--holdout-objects` objects are held out whole; on the others the outcome model is
fitted to its own inputs (`plain`), with the support numbers (`support`) and with both priors
(`support_analytic`), and tilt classifiers (rl/primitive/outcome/tilt_classifier.py) on the box-and-contact
features with and without the support numbers. Every held-out state's choice is scored in the
rewards the simulator measured (`chosen`, per primitive), choosing by each model's predicted
reward, alone and blended by a classifier (outcome.tilt_blend: (1 - p) x reward + p x the mean
measured reward of the training rows that tilted). The analytic model's own figures use every
state (it fits nothing; its two gains were picked on these data, so they flatter it).

The data store no clouds: each state's is rebuilt from the library's cloud.npy (a fixed 512 of
its points, the observation's count), scaled by the episode's box against the library's and
placed at the stored pose. `--library` gives one library per `--data` folder.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from distill_scaling import held_out_objects, select_states  # noqa: E402
from outcome_ensemble import load_study  # noqa: E402
from outcome_sources import roc_auc  # noqa: E402

from corn_drake.rl.primitive.outcome.lookahead_distill import scores_quality  # noqa: E402
from corn_drake.rl.primitive.outcome.model import (SCALE, data_after, data_candidates,  # noqa: E402
                                         fit_network, model_inputs, predicted_rewards,
                                         rotation_matrices)
from corn_drake.rl.primitive.outcome.tilt_classifier import (box_contact_features, data_tilted,  # noqa: E402
                                           fit_tilt_classifier)
from corn_drake.storage.atomic_files import write_json  # noqa: E402
from corn_drake.systems.primitive_executor import pre_contact_point  # noqa: E402
from corn_drake.transforms import quat_wxyz_to_matrix  # noqa: E402

CLOUD_POINTS = 512  # the observation's (env.scene.object.cloud_points)
SUPPORT_BANDS = (0.003, 0.01, 0.02)  # m over the lowest point
FINGER_RADIUS = 0.012  # m: the closed fingers' half width across the push
LIMIT_SURFACE_BAND = 0.004  # m: the points that carry the object's weight, for the limit surface
TRAVEL_GAIN, SUPPORT_GAIN = 0.5, 1.5
SUBSTEPS = 16


def state_clouds(data: dict, libraries: list[Path]) -> tuple[np.ndarray, np.ndarray]:
    """(points (S, N, 3), outward normals (S, N, 3)) of every state's object, world frame."""
    cache, points, normals = {}, [], []
    for s, tagged in enumerate(data["object"]):
        folder, name = tagged.split(":", 1)
        if tagged not in cache:
            path = libraries[int(folder)] / name
            if not (path / "cloud.npy").is_file():
                raise SystemExit(f"--library {libraries[int(folder)]}: no {name}/cloud.npy")
            cloud = np.load(path / "cloud.npy")
            keep = np.random.default_rng(0).choice(len(cloud), CLOUD_POINTS, replace=False)
            cache[tagged] = (cloud[keep], np.load(path / "bbox_corners.npy"))
        cloud, box = cache[tagged]
        scale = np.ptp(data["outcome_corners"][s], 0) / np.ptp(box, 0)
        R = quat_wxyz_to_matrix(data["outcome_pose"][s, 3:])
        points.append((cloud[:, :3] * scale) @ R.T + data["outcome_pose"][s, :3])
        n = cloud[:, 3:] / scale  # a scaled surface's normals scale inversely
        normals.append((n / np.linalg.norm(n, axis=1, keepdims=True)) @ R.T)
    return np.stack(points), np.stack(normals)


def _directions(motion: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(along (R, 2), across (R, 2)): the push's horizontal heading and its left normal."""
    length = np.linalg.norm(motion[:, :2], axis=1, keepdims=True)
    along = np.where(length > 1e-9, motion[:, :2] / np.maximum(length, 1e-9), [1.0, 0.0])
    return along, np.stack([-along[:, 1], along[:, 0]], 1)


def support_features(points: np.ndarray, aim: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """(R, 19) the module docstring's support numbers; points (R, N, 3) world, aim (R, 3)."""
    along, across = _directions(motion)
    lowest = points[:, :, 2].min(1)
    centroid = points.mean(1)
    centroid_height, aim_height = centroid[:, 2] - lowest, aim[:, 2] - lowest
    offset = points[:, :, :2] - centroid[:, None, :2]
    ahead = np.einsum("rnk,rk->rn", offset, along)
    beside = np.abs(np.einsum("rnk,rk->rn", offset, across))
    out = [centroid_height, aim_height]
    for band in SUPPORT_BANDS:
        low = points[:, :, 2] < (lowest + band)[:, None]
        front = np.where(low, ahead, -np.inf).max(1)
        back = -np.where(low, ahead, np.inf).min(1)
        side = np.where(low, beside, -np.inf).max(1)
        out += [front, back, side, front / np.maximum(aim_height, 0.005) / SCALE,
                front / np.maximum(centroid_height, 0.005) / SCALE]
    aim_offset = aim[:, :2] - centroid[:, :2]
    out += [np.einsum("rk,rk->r", aim_offset, along), np.einsum("rk,rk->r", aim_offset, across)]
    return np.stack(out, 1) * SCALE


def _turned(v: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]], 1)


def planar_push(points, normals, pre, push, physics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(planar displacement (R, 2), yaw (R,), touched (R,)) of the module docstring's analytic
    push: points / normals (R, N, 3) world, pre (R, 3) the pre-contact point, push (R, 3) the
    hand's displacement, physics (R, 5: mass, table / object / finger friction, restitution)."""
    R = len(pre)
    rows = np.arange(R)
    along, _ = _directions(push)
    length = np.linalg.norm(push[:, :2], axis=1)
    offset = points[:, :, :2] - pre[:, None, :2]
    ahead = np.einsum("rnk,rk->rn", offset, along)
    aside = np.abs(offset[:, :, 0] * along[:, None, 1] - offset[:, :, 1] * along[:, None, 0])
    tip_z = pre[:, None, 2] + np.clip(ahead / np.maximum(length, 1e-9)[:, None], 0, 1) * \
        push[:, None, 2]
    hit = (aside < FINGER_RADIUS) & (ahead > 0) & (ahead < length[:, None]) & \
        (points[:, :, 2] > tip_z - 0.005)
    first = np.where(hit, ahead, np.inf).min(1)
    touched = np.isfinite(first)
    # The contact: of the points the finger meets first (within 3 mm), the one nearest its
    # path's centre line (a flat face pushed square on is not turned by where a sample lies).
    front = hit & (ahead < (first + 0.003)[:, None])
    contact = np.where(front, aside, np.inf).argmin(1)
    travel = np.where(touched, length - np.where(touched, first, 0), 0.0)
    # The contact's inward normal (a near-vertical normal: straight along the push).
    normal = -normals[rows, contact, :2]
    size = np.linalg.norm(normal, axis=1, keepdims=True)
    inward = np.where(size > 0.3, normal / np.maximum(size, 1e-9), along)
    centroid = points.mean(1)[:, :2]
    lowest = points[:, :, 2].min(1)
    carrying = points[:, :, 2] < (lowest + LIMIT_SURFACE_BAND)[:, None]
    reach = np.linalg.norm(points[:, :, :2] - centroid[:, None], axis=2)
    c = SUPPORT_GAIN * np.maximum((reach * carrying).sum(1) / carrying.sum(1), 0.005)
    cone = np.arctan(2 * physics[:, 2] * physics[:, 3] / (physics[:, 2] + physics[:, 3]))
    arm = points[rows, contact, :2] - centroid
    moved, yaw = np.zeros((R, 2)), np.zeros(R)
    step = TRAVEL_GAIN * travel / SUBSTEPS
    active = touched.copy()
    for _ in range(SUBSTEPS):
        # Quasi-static: the contact point's velocity is A f for a contact force f, with the
        # limit surface's A = I + perp(r) perp(r)^T / c^2 (force and moment scaled alike).
        perp = np.stack([-arm[:, 1], arm[:, 0]], 1)
        A = np.eye(2)[None] + np.einsum("ri,rj->rij", perp, perp) / (c ** 2)[:, None, None]
        force = np.linalg.solve(A, along[..., None])[..., 0]  # sticking: the point moves along
        into = np.einsum("rk,rk->r", along, inward)
        active &= into > 0.05  # the object turned away from the finger: contact lost
        sticks = np.einsum("rk,rk->r", force, inward) >= \
            np.cos(cone) * np.linalg.norm(force, axis=1)
        side = np.sign(inward[:, 0] * force[:, 1] - inward[:, 1] * force[:, 0])
        edge = _turned(inward, side * cone)  # sliding: the friction cone's edge on that side
        gain = into / np.maximum(np.einsum("rij,rj,ri->r", A, edge, inward), 1e-9)
        force = np.where(sticks[:, None], force, edge * gain[:, None])
        turn = np.einsum("rk,rk->r", perp, force) / c ** 2 * active * step
        moved += force * (active * step)[:, None]
        yaw += turn
        arm, inward = _turned(arm, turn), _turned(inward, turn)
    return moved, yaw, touched


def analytic_prediction(moved_push, yaw, now):
    """planar_push's outcome (its displacement already in the push frame, decimetres) as an
    outcome model's prediction."""
    rotation = torch.as_tensor(np.pad(yaw[:, None], ((0, 0), (2, 0))), dtype=torch.float32)
    displacement = torch.as_tensor(moved_push, dtype=torch.float32)
    return now @ rotation_matrices(rotation).transpose(1, 2) + displacement[:, None], \
        displacement, rotation


def held_out_prediction(features, now, target, train, test, updates: int, seed: int):
    """(the prediction for rows `test`, its mean keypoint error in metres) of an outcome model
    fitted on rows `train` of `features` (fit_network, `updates` updates, `seed`)."""
    model = fit_network(features[train], now[train], target[train], updates, seed)
    with torch.no_grad():
        prediction = model(features[test], now[test])
    error = np.linalg.norm(prediction[0].numpy() - target[test].numpy(), axis=2).mean() / SCALE
    return prediction, float(error)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", help="the primitive run whose task and progress reward score")
    parser.add_argument("--data", type=Path, nargs="+", required=True)
    parser.add_argument("--library", type=Path, nargs="+", required=True)
    parser.add_argument("--holdout-objects", type=int, default=30)
    parser.add_argument("--splits", type=int, default=3)
    parser.add_argument("--updates", type=int, default=2000)
    parser.add_argument("--classifier-updates", type=int, default=4000)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    if len(args.library) != len(args.data):
        raise SystemExit(f"--library: {len(args.library)} libraries for {len(args.data)} --data "
                         "folders (one each)")
    torch.set_num_threads(1)
    base, data, objects = load_study(args.run, args.data, args.holdout_objects)
    task, progress = base.env.task, base.primitive.progress_reward
    points, normals = state_clouds(data, args.library)
    c = data_candidates(data)
    state = data["state"]
    origin = data["outcome_pose"][state, :3]
    aim = c.aim + origin
    x, now, frames = model_inputs(c, tokens=False)
    target = data_after(data, frames)
    support = torch.as_tensor(support_features(points[state], aim, c.motion),
                              dtype=torch.float32)
    pre = np.stack([pre_contact_point(a, n, base.primitive) for a, n in zip(aim, c.normal)])
    moved, yaw, touched = planar_push(points[state], normals[state], pre,
                                      c.motion * base.primitive.push_distance, c.physics)
    moved_push = np.einsum("rij,rj->ri", frames, np.pad(moved, ((0, 0), (0, 1)))) * SCALE
    analytic = analytic_prediction(moved_push, yaw, now)
    analytic_inputs = torch.as_tensor(np.concatenate([moved_push[:, :2], yaw[:, None],
                                                      touched[:, None]], 1), dtype=torch.float32)
    tilted = data_tilted(data)
    box = box_contact_features(c)
    no_motion = np.linalg.norm(now.numpy() - target.numpy(), axis=2).mean(1) / SCALE
    analytic_error = np.linalg.norm(analytic[0].numpy() - target.numpy(), axis=2).mean(1) / SCALE
    analytic_rewards = predicted_rewards(c, frames, analytic, task, progress)
    report = {"run": str(args.run), "data": [str(d) for d in args.data],
              "libraries": [str(d) for d in args.library], "states": int(len(points)),
              "rows": int(len(state)), "objects": len(objects),
              "holdout_objects": args.holdout_objects, "updates": args.updates,
              "classifier_updates": args.classifier_updates,
              "gains": {"travel": TRAVEL_GAIN, "support": SUPPORT_GAIN},
              "analytic_every_state": {
                  "touched": float(touched.mean()),
                  "keypoint_error_m": float(analytic_error.mean()),
                  "no_motion_error_m": float(no_motion.mean()),
                  "keypoint_error_untilted_m": float(analytic_error[~tilted].mean()),
                  "no_motion_error_untilted_m": float(no_motion[~tilted].mean()),
                  **scores_quality(analytic_rewards, data)},
              "splits": []}
    inputs = {"plain": x, "support": torch.cat([x, support], 1),
              "support_analytic": torch.cat([x, support, analytic_inputs], 1)}
    for split in range(args.splits):
        held, rest = held_out_objects(objects, args.holdout_objects, split)
        fitted = np.isin(data["object"][state], rest)
        train, test = np.flatnonzero(fitted), np.flatnonzero(~fitted)
        held_out = select_states(data, np.flatnonzero(np.isin(data["object"], held)))
        tilted_reward = float(data["reward"][train][tilted[train]].mean())
        row = {"split": split, "tilted_reward": tilted_reward, "tilt_auc": {}, "chosen": {},
               "keypoint_error_m": {"no_motion": float(no_motion[test].mean())}}
        probability = {}
        for name, features in (("box", box), ("box_support", torch.cat([box, support], 1))):
            classifier = fit_tilt_classifier(features[train], tilted[train],
                                             args.classifier_updates, split)
            with torch.no_grad():
                probability[name] = torch.sigmoid(classifier(features[test])).numpy()
            row["tilt_auc"][name] = roc_auc(tilted[test], probability[name])
        rewards = {"analytic": analytic_rewards[test]}
        held_c = data_candidates(held_out)  # its rows are `test`, in the same order
        for name, features in inputs.items():
            prediction, row["keypoint_error_m"][name] = held_out_prediction(
                features, now, target, train, test, args.updates, split)
            rewards[name] = predicted_rewards(held_c, frames[test], prediction, task, progress)
        for name, r in rewards.items():
            row["chosen"][name] = scores_quality(r, held_out)["chosen"]
            for classifier, p in probability.items():
                row["chosen"][f"{name}+blend_{classifier}"] = scores_quality(
                    (1 - p) * r + p * tilted_reward, held_out)["chosen"]
        row["chosen"]["lookahead"] = scores_quality(held_out["reward"], held_out)["best"]
        report["splits"].append(row)
        print(f"split {split}: {row}", flush=True)
    report["mean"] = {key: {k: float(np.mean([r[key][k] for r in report["splits"]]))
                            for k in report["splits"][0][key]}
                      for key in ("tilt_auc", "chosen", "keypoint_error_m")}
    write_json(args.out, report)
    print(f"wrote {args.out}: {report['mean']}")


if __name__ == "__main__":
    main()
