"""Whole episodes of a policy: the one episode runner and the evaluation report.

run_episode runs one episode of a TeacherEnv or StudentEnv, with the policy inside the diagram
(an env built with `agent=` / `student=`: a PolicySystem / StudentPolicySystem acts) or stepped
through the gymnasium API (an agent with act(obs), or a callable obs -> action), optionally
recorded to Meshcat HTML. evaluate runs episodes round-robin over objects and returns the report
`corn-drake evaluate` writes, for the teacher (a TeacherDiagramConfig) or the student (a
StudentDiagramConfig: the same report plus its perception and pose-tracking errors); the demo,
notebooks and tests use the same two functions.
"""

from __future__ import annotations

import dataclasses
import json
import zlib
from collections import defaultdict
from pathlib import Path
from typing import Callable

import numpy as np

from corn_drake.errors import InputError
from corn_drake.evaluation.failures import failure_category, motion_summary


@dataclasses.dataclass
class EpisodeResult:
    steps: int
    total_reward: float
    status: dict  # the last step's task status (systems/reward.STATUS_FIELDS)
    sim_error: str | None = None
    recording: Path | None = None
    # info["tracking"] of every step (StudentEnv: tracked vs true object pose), empty otherwise.
    tracking: list[dict] = dataclasses.field(default_factory=list)
    # The object's pose ([p, q_wxyz]) at the start and the end, and the episode's goal.
    start_pose: np.ndarray | None = None
    end_pose: np.ndarray | None = None
    goal_pose: np.ndarray | None = None
    end_speed: dict | None = None  # the object's speed at the end (DiagramEnv.object_speed)

    @property
    def success(self) -> bool:
        return bool(self.status.get("success", 0) > 0)


def run_episode(env, policy=None, *, seed: int | None = None, max_steps: int | None = None,
                record_path: str | Path | None = None) -> EpisodeResult:
    """Resets `env` (a TeacherEnv or StudentEnv) and steps it until the episode ends or
    `max_steps`.

    policy: None when the env's policy is inside its diagram; otherwise an agent with
    act(obs) or a callable obs -> normalised action. record_path: save the episode as Meshcat
    HTML there (the env must have been built with a Meshcat).
    """
    if env.policy_in_diagram != (policy is None):
        raise ValueError("run_episode: pass a policy exactly when the env has none inside its "
                         "diagram (TeacherEnv(..., agent=...) holds one)")
    act: Callable | None = getattr(policy, "act", policy)
    if record_path is not None and env.meshcat is None:
        raise ValueError("run_episode: recording needs an env built with meshcat=Meshcat()")
    obs, info = env.reset(seed=seed)
    start_pose = env.object_pose()
    if env.meshcat is not None:  # the goal, the hand's path and a camera on the push
        from corn_drake.viz.meshcat import show_goal

        show_goal(env.meshcat, env.scene.object_spec, env.episode.goal_pose, start_pose)
        env.hand_path = [env.tool_position()]
    if record_path is not None:
        env.meshcat.StartRecording(set_visualizations_while_recording=False)
    total, steps, status, error, tracking = 0.0, 0, info.get("status", {}), None, []
    limit = max_steps or env.teacher_cfg.task.episode_steps
    while steps < limit:
        obs, reward, terminated, truncated, info = env.step(None if act is None else act(obs))
        total += reward
        steps += 1
        status = info.get("status", status)
        error = info.get("sim_error")
        if "tracking" in info:
            tracking.append(info["tracking"])
        if terminated or truncated:
            break
    recording = None
    if env.meshcat is not None:
        from corn_drake.viz.meshcat import show_path

        show_path(env.meshcat, env.hand_path)
        env.hand_path = None
    if record_path is not None:
        from corn_drake.viz.meshcat import save_recording

        env.meshcat.StopRecording()
        recording = save_recording(env.meshcat, record_path)
    return EpisodeResult(steps=steps, total_reward=total, status=status, sim_error=error,
                         recording=recording, tracking=tracking, start_pose=start_pose,
                         end_pose=env.object_pose(), goal_pose=np.asarray(env.episode.goal_pose),
                         end_speed=env.object_speed())


def policy_env(cfg, spec, meshcat, policy, stochastic: bool = False, seed: int | None = None,
               attention: bool = False):
    """The evaluation env of `cfg` with `policy` acting inside its diagram: for a
    TeacherDiagramConfig a TeacherEnv holding a PolicySystem (`policy`: an agent with act(obs));
    for a StudentDiagramConfig a StudentEnv holding a StudentPolicySystem (`policy`: a
    StudentPolicy in eval mode). `seed` replaces the teacher part's seed (the object cloud
    subset, the episode generator's default). `attention`: the teacher's attention view
    (TeacherEnv)."""
    from corn_drake.config.student import StudentDiagramConfig
    from corn_drake.rl.envs.teacher_env import TeacherEnv
    from corn_drake.rl.envs.student_env import StudentEnv

    if getattr(policy, "kind", None) == "primitive":
        # The contact-primitive policy: its executor and policy systems in the teacher's
        # diagram (builders/primitive.py), with the executor settings it was trained with.
        from corn_drake.rl.envs.primitive_env import PrimitiveEnv

        if stochastic or attention:
            raise InputError("the primitive policy acts greedily and has no cross-attention: "
                             "--stochastic and --attention do not apply (its Meshcat view "
                             "shows its contact point, push and scores)")
        if seed is not None:
            cfg = dataclasses.replace(cfg, seed=seed)
        return PrimitiveEnv(cfg, policy.primitive_config, spec, meshcat, agent=policy)
    if isinstance(cfg, StudentDiagramConfig):
        if seed is not None:
            cfg = dataclasses.replace(cfg, teacher=dataclasses.replace(cfg.teacher, seed=seed))
        return StudentEnv(cfg, spec, meshcat, student=policy, stochastic_policy=stochastic)
    if seed is not None:
        cfg = dataclasses.replace(cfg, seed=seed)
    return TeacherEnv(cfg, spec, meshcat, policy, stochastic, attention)


def _summary(values) -> dict:
    values = np.asarray(values, float)
    if values.size == 0:
        return {"mean": None, "median": None, "max": None}
    return {"mean": float(values.mean()), "median": float(np.median(values)),
            "max": float(values.max())}


def tracking_summary(steps: list[dict]) -> dict:
    """Tracked vs true object pose over `steps` (StudentEnv info["tracking"] dicts): mean,
    median and max of the position error (m) and the orientation error (deg: the full rotation,
    so for an object with a symmetry axis it includes the unobservable roll), the fraction of
    steps the tracker trusted its ICP result, and the step count."""
    from corn_drake.rl.envs.vec_env import TRACKING_STATS

    out = {k: _summary([t[k] for t in steps]) for k in TRACKING_STATS}
    out["ok_fraction"] = float(np.mean([t["ok"] > 0 for t in steps])) if steps else None
    out["steps"] = len(steps)
    return out


def episode_seed(seed: int, object_id: str, repeat: int) -> int:
    """The seed of the `repeat`-th evaluation episode on `object_id`: a function of the object's
    id and not of its place in the list, so an object's episodes are the same whichever other
    objects are evaluated beside it (tests/test_shipped_weights.py re-runs two of a card's
    objects and compares them episode by episode)."""
    return (seed + 10_007 * repeat + zlib.crc32(object_id.encode())) % 2**31


def evaluate(agent, cfg, objects, episodes: int | range, record: int, seed: int, out_dir: Path,
             *, stochastic: bool = False, attention: bool = False, meshcat=None,
             progress: bool = False, rows_path: Path | None = None,
             settings: dict | None = None) -> dict:
    """Runs the episodes `episodes` (a range of k, or a count from 0) of `agent` round-robin
    over `objects` [(object id, ObjectSpec)] in the evaluation diagram of `cfg` (policy_env: a
    TeacherDiagramConfig and a teacher agent, or a StudentDiagramConfig and a StudentPolicy);
    episodes k < `record` are saved as Meshcat HTML in `out_dir`. Episode k is the
    (k // len(objects))-th on its object, seeded episode_seed(seed, object id, that count) and
    recorded in its row. The policy runs inside the diagram; with `stochastic` it samples the
    actions, the noise drawn from the episode's seed. With `attention` (a teacher that
    cross-attends: TeacherAgent.has_attention), its attention is painted on the object's cloud
    every step, in the recordings and in the live Meshcat (made even when `record` is 0).
    `meshcat`: the Meshcat to draw in (the caller's, e.g. one it keeps open after the
    episodes); made here when recording or attention needs one. With `progress`, a tqdm bar
    over the episodes (on stderr) counts the successes so far.

    With `rows_path` (REPORT.rows.jsonl, episode_rows.py) each finished episode's row is
    appended at once under the header of `settings` (what makes the evaluation: the same
    settings resume it, other settings are refused), and the episodes already there are not
    played again.

    Returns the report (policy_report): the keys every report shares (report_core.py), the
    task's name and action_step, and a student's perception and tracking. Interrupted (Ctrl-C,
    SIGTERM) after some episodes, the interrupt goes on up carrying the report of the finished
    ones, complete false, as .partial_report.
    """
    from corn_drake.evaluation.episode_rows import append_row, claim_range, read_rows
    from corn_drake.rl.envs.student_env import StudentEnv

    episodes = range(episodes) if isinstance(episodes, int) else episodes
    if not objects:
        raise InputError("evaluate: no objects to evaluate on")
    if len(episodes) < 1:
        raise InputError(f"evaluate: no episodes in [{episodes.start}, {episodes.stop})")
    if attention and not getattr(agent, "has_attention", False):
        raise InputError(f"evaluate: attention needs a policy that cross-attends over patches "
                         f"(corn, e2e), got {getattr(agent, 'kind', type(agent).__name__)!r}")
    rows = []
    if rows_path is not None:
        settings = json.loads(json.dumps(settings))  # as it reads back
        rows = read_rows(rows_path, settings)
        claim_range(rows_path, settings, episodes, rows)  # rows outside `episodes`: refused
    done = {r["episode"] for r in rows}
    if meshcat is None and (record > 0 or attention):
        from pydrake.geometry import Meshcat

        meshcat = Meshcat()
    from tqdm import tqdm

    envs = {}
    bar = tqdm(total=len(episodes), initial=len(done), desc="episodes", unit="episode",
               disable=not progress)
    interrupted = None
    try:
        for k in episodes:
            if k in done:
                continue
            object_id, spec = objects[k % len(objects)]
            if object_id not in envs:
                envs[object_id] = policy_env(cfg, spec, meshcat, agent, stochastic, seed, attention)
            env = envs[object_id]
            path = out_dir / f"episode_{k:03d}_{object_id}.html" if k < record else None
            episode_seed_k = episode_seed(seed, object_id, k // len(objects))
            result = run_episode(env, seed=episode_seed_k, record_path=path)
            row = {"episode": k, "object": object_id, "seed": episode_seed_k,
                   "success": result.success,
                   "steps": result.steps, "return": result.total_reward,
                   "position_error": result.status.get("position_error"),
                   "orientation_error": result.status.get("orientation_error"),
                   "sim_error": result.sim_error,
                   "out_of_workspace": bool(result.status.get("out_of_workspace", 0) > 0),
                   "motion": motion_summary(result.start_pose, result.end_pose,
                                            result.goal_pose),
                   "end_speed": result.end_speed,
                   "recording": None if result.recording is None else str(result.recording)}
            row["failure"] = failure_category(row, env.teacher_cfg.task)
            if isinstance(env, StudentEnv):  # the student's pose tracking is part of its result
                row["tracking"] = tracking_summary(result.tracking)
                row[TRACKING_STEPS] = tracking_columns(result.tracking)
            if rows_path is not None:
                append_row(rows_path, row)
            rows.append(row)
            bar.set_postfix(successes=sum(r["success"] for r in rows), refresh=False)
            bar.update()
    except BaseException as e:  # noqa: BLE001 - Ctrl-C, SIGTERM (cli.Interrupted), not errors
        if isinstance(e, Exception) or not rows:
            raise
        # The episodes finished so far make a report, marked partial; the caller writes it
        # (e.partial_report) and the interrupt goes on up.
        interrupted = e
    bar.close()
    report = policy_report(sorted(rows, key=lambda r: r["episode"]), episodes, report_facts(cfg))
    if interrupted is not None:
        report["complete"] = False
        interrupted.partial_report = report
        raise interrupted
    return report


# A student's rows keep the tracking of every step (columns of TRACKING_STATS, as measured:
# JSON gives a float back exactly) under this key, so a report of resumed or merged rows sums
# its tracking over every step, as one process's does; the report's own rows leave it out.
TRACKING_STEPS = "tracking_steps"


def tracking_columns(steps: list[dict]) -> dict[str, list]:
    from corn_drake.rl.envs.vec_env import TRACKING_STATS

    return {**{k: [float(t[k]) for t in steps] for k in TRACKING_STATS},
            "ok": [int(t["ok"] > 0) for t in steps]}


def tracking_steps_of(rows: list[dict]) -> list[dict]:
    """Every step's tracking of `rows`, as StudentEnv's info["tracking"] gives them."""
    steps = []
    for r in rows:
        columns = r.get(TRACKING_STEPS) or {}
        keys = list(columns)
        steps += [dict(zip(keys, values)) for values in zip(*(columns[k] for k in keys))]
    return steps


def report_facts(cfg) -> dict:
    """What a policy report says of the diagram its episodes ran in (`cfg`): the task's name,
    the action's translation step at |a| = 1, and a student's segmentation (None for a
    teacher). Kept in the rows file's settings too, so merged parts report the same."""
    from corn_drake.config.student import StudentDiagramConfig

    student = isinstance(cfg, StudentDiagramConfig)
    teacher_cfg = cfg.teacher if student else cfg
    return {"task": teacher_cfg.task.name,
            "action_step": teacher_cfg.controller.max_position_delta,
            "perception": cfg.segmentation.mode if student else None}


def policy_report(rows: list[dict], requested, facts: dict) -> dict:
    """The report of a policy's `rows` (sorted by episode) of the episodes `requested`, in the
    diagram `facts` describes (report_facts): the task, its action step, the keys every report
    shares (report_core.episode_report), and for a student its perception and its tracking
    over every step of every episode."""
    from corn_drake.evaluation.report_core import episode_report

    report = {"task": facts["task"], "action_step": facts["action_step"],
              **episode_report([{k: v for k, v in r.items() if k != TRACKING_STEPS}
                                for r in rows], requested)}
    if facts.get("perception") is not None:
        report.update({"perception": facts["perception"],
                       "tracking": tracking_summary(tracking_steps_of(rows))})
    return report


def success_by_group(episodes: list[dict], groups: dict[str, str]) -> dict:
    """Group -> {success_rate, episodes, objects} over report rows; `groups` maps object id -> group
    (assets.library.object_groups), so "unseen" splits into new families and new members."""
    by_group: dict[str, list[dict]] = defaultdict(list)
    for row in episodes:
        if row["object"] not in groups:
            raise InputError(f"episode {row['episode']}: object {row['object']!r} has no group")
        by_group[groups[row["object"]]].append(row)
    return {g: {"success_rate": float(np.mean([r["success"] for r in rows])),
                "episodes": len(rows), "objects": len({r["object"] for r in rows})}
            for g, rows in sorted(by_group.items())}
