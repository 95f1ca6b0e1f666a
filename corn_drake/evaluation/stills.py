"""Gallery stills of one episode: a teacher's episode run by evaluate's own episode runner (so
the outcome is the one evaluate reports for the seed), and the steps asked for rendered by
viz/gallery.py's camera with the cloud painted by the policy's attention.

A contact-primitive policy (rl/primitive/agent.py) has no attention: its stills paint the cloud
by the policy's scores over its candidate contact locations (each point takes its nearest
location's score) and mark the contact point it chose. Its episode runs in evaluate's own env,
policy_env's PrimitiveEnv with the policy inside the diagram, so here too the outcome is
evaluate's for the seed.

Each episode is recorded once (EpisodeFrames: every observation's plant positions, cloud and
colours) and then rendered at the steps asked for: the stills, and for `gallery --animate`
every step again at a smaller size (render_frames), so the PNG and the GIF show one episode.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from corn_drake.contract import POSITION_DIM
from corn_drake.evaluation.episodes import policy_env, run_episode
from corn_drake.rl.envs.teacher_env import TeacherEnv
from corn_drake.viz.attention_view import viridis_rgb
from corn_drake.viz.gallery import (HEIGHT, POINT_RADIUS_PX, WIDTH, Still, StillCamera, paint,
                                    pick_steps, side_view)

# The primitive policy's chosen contact point: a colour neither viridis nor the goal's red uses.
CONTACT_COLOUR = np.array([255, 0, 255], np.uint8)


@dataclasses.dataclass
class Frame:
    step: int
    positions: np.ndarray  # the env plant's positions at this observation
    cloud: np.ndarray  # (N, 3) world-frame cloud the policy read
    colours: np.ndarray  # (N, 3) uint8 the cloud is painted in
    marks: list  # (point (3,), colour (3,) uint8) drawn over everything


@dataclasses.dataclass
class EpisodeFrames:
    frames: list[Frame]  # every observation of the episode, the one it ended on last
    start: np.ndarray  # (7,) the object's initial pose
    goal: np.ndarray  # (7,) its goal pose
    summary: dict


def episode_stills(agent, cfg, spec, seed: int, steps_wanted: str = "start,middle,end"
                   ) -> tuple[list[Still], dict]:
    """Runs one episode of `agent` (mean actions) on `spec` in the env of `cfg` (a
    TeacherDiagramConfig) and renders the stills of `steps_wanted` ("start", "middle", "end",
    or step numbers). Returns (stills, episode summary)."""
    episode = record_episode(agent, cfg, spec, seed)
    picks = pick_steps(steps_wanted, len(episode.frames))
    return render_frames(episode, cfg.scene, spec, picks), episode.summary


def record_episode(agent, cfg, spec, seed: int) -> EpisodeFrames:
    """One episode of `agent` (mean actions) run by evaluate's episode runner, every
    observation kept. A contact-primitive agent's goes to record_primitive_episode."""
    if getattr(agent, "kind", None) == "primitive":
        return record_primitive_episode(agent, cfg, spec, seed)
    env = TeacherEnv(cfg, spec)
    frames = []  # (step, plant positions, cloud, point scores) of every observation

    def act_and_keep(obs):
        action, attention = agent.act_and_attend(obs)
        frames.append((len(frames), env.scene.plant.GetPositions(env._plant_context).copy(),
                       obs["cloud"].reshape(-1, POSITION_DIM).copy(), attention.point_scores()))
        return action

    # evaluate's own episode runner, so the outcome is the one evaluate reports for this seed.
    result = run_episode(env, act_and_keep, seed=seed)
    act_and_keep(env._observation())  # the observation the episode ended on: the "end" still
    return EpisodeFrames([Frame(step, positions, cloud, viridis_rgb(scores), [])
                          for step, positions, cloud, scores in frames],
                         np.array(env.episode.initial_object_pose, float),
                         np.array(env.episode.goal_pose, float), _summary(seed, result))


def render_frames(episode: EpisodeFrames, scene_cfg, spec, picks: list[int],
                  width: int = WIDTH, height: int = HEIGHT) -> list[Still]:
    """The frames `picks` of `episode` rendered from the side of its push (side_view), each
    with the goal copy of the object, the cloud painted and its marks drawn. Points shrink with
    the picture so a small animation frame is not covered by them."""
    camera = StillCamera(scene_cfg, spec, *side_view(episode.start, episode.goal, spec.radius),
                         width=width, height=height)
    radius = max(1, round(POINT_RADIUS_PX * height / HEIGHT))
    stills = []
    for k in picks:
        f = episode.frames[k]
        image, painted = _painted_still(camera, f.positions, f.cloud, f.colours, episode.goal,
                                        f.marks, radius)
        stills.append(Still(f.step, image, painted))
    return stills


def _summary(seed: int, result) -> dict:
    """What a gallery entry says of its episode, as a report row would: its end speed too, so
    a picture of a success says whether the object ended at rest on its goal."""
    from corn_drake.config.primitive import at_rest

    speed = result.end_speed
    return {"seed": seed, "steps": result.steps, "success": result.success,
            "position_error": result.status.get("position_error"), "end_speed": speed,
            "ended_at_rest": None if speed is None else bool(at_rest(speed))}


def _painted_still(camera, positions, cloud, colours, goal_pose, marks=(),
                   radius: int = POINT_RADIUS_PX) -> tuple[np.ndarray, int]:
    """The render of `positions` with the goal copy of the object (goal_pose (7,)), the
    visible cloud points in `colours`, then each (point, colour) of `marks` drawn over
    everything. Returns (image, points painted)."""
    rgb, depth = camera.render_with_goal(positions, goal_pose)
    pixels, z = camera.project(cloud)
    image, painted = paint(rgb, depth, pixels, z, colours, radius=radius)
    for point, colour in marks:
        pixel, point_z = camera.project(np.asarray(point, float)[None])
        image, _ = paint(image, np.full(depth.shape, np.inf), pixel, point_z, colour[None],
                         radius=2 * radius)
    return image, painted


class _DecisionLog:
    """Stands in for a PrimitiveAgent inside the evaluation diagram and keeps every choice it
    makes, numbered by the latest observation recorded when it was made (the one the policy
    read). Everything else is the agent's, so the diagram and the episode are evaluate's."""

    def __init__(self, agent, frames: list):
        self._agent, self._frames = agent, frames
        self.decisions: list[tuple[int, dict]] = []

    def __getattr__(self, name):
        return getattr(self._agent, name)

    def choose(self, obs):
        choice = self._agent.choose(obs)
        self.decisions.append((max(len(self._frames) - 1, 0), choice))
        return choice

    def shown_at(self, frame: int) -> dict | None:
        """The choice a still of observation `frame` shows: the last one made from an
        observation up to it (during a primitive, the one being executed), or the first one
        when none was made yet."""
        made = [c for k, c in self.decisions if k <= frame]
        return made[-1] if made else (self.decisions[0][1] if self.decisions else None)


def location_colours(cloud: np.ndarray, choice: dict | None) -> np.ndarray:
    """(N, 3) uint8: each cloud point in viridis of its nearest candidate location's score
    (min-max over the locations, as the scores are Q values of either sign), all dark when no
    choice was made."""
    if choice is None:
        return viridis_rgb(np.zeros(len(cloud)))
    scores = np.asarray(choice["scores"], float)
    spread = scores.max() - scores.min()
    relative = (scores - scores.min()) / spread if spread > 0 else np.zeros_like(scores)
    centres = cloud[np.asarray(choice["candidates"], int)]
    nearest = np.linalg.norm(cloud[:, None] - centres[None], axis=-1).argmin(axis=1)
    return viridis_rgb(relative[nearest])


def record_primitive_episode(agent, cfg, spec, seed: int) -> EpisodeFrames:
    """record_episode for a contact-primitive agent: one episode in evaluate's env (policy_env:
    the policy inside the diagram, one env step per policy period), each frame's cloud coloured
    by the scores of the choice it shows (_DecisionLog.shown_at) and that choice's contact point
    marked in magenta. The summary adds `primitives`, the primitives the episode ran."""
    from corn_drake.rl.envs.primitive_env import STATUS_LAYOUT

    frames = []  # (step, plant positions, cloud) of every observation
    log = _DecisionLog(agent, frames)
    env = policy_env(cfg, spec, None, log)

    def keep_frame():
        frames.append((len(frames), env.scene.plant.GetPositions(env.plant_context).copy(),
                       env._observation()["cloud"].reshape(-1, POSITION_DIM).copy()))

    env_step = env.step

    def step_and_keep(action=None):
        result = env_step(action)
        keep_frame()
        return result

    env.step = step_and_keep  # run_episode steps the env itself; each step leaves a frame
    env_reset = env.reset

    def reset_and_keep(**kwargs):
        frames.clear()
        result = env_reset(**kwargs)
        keep_frame()
        return result

    env.reset = reset_and_keep
    result = run_episode(env, None, seed=seed)
    primitives = int(round(env.executor_status()[STATUS_LAYOUT["count"]]))
    kept = []
    for k, (step, positions, cloud) in enumerate(frames):
        choice = log.shown_at(k)
        marks = [] if choice is None else [(cloud[choice["point"]], CONTACT_COLOUR)]
        kept.append(Frame(step, positions, cloud, location_colours(cloud, choice), marks))
    return EpisodeFrames(kept, np.array(env.episode.initial_object_pose, float),
                         np.array(env.episode.goal_pose, float),
                         {**_summary(seed, result), "primitives": primitives})
