"""Gallery stills of one episode: a teacher's episode run by evaluate's own episode runner (so
the outcome is the one evaluate reports for the seed), and the steps asked for rendered by
viz/gallery.py's camera with the cloud painted by the policy's attention.

A contact-primitive policy (rl/primitive/agent.py) has no attention: its stills paint the cloud
by the policy's scores over its candidate contact locations (each point takes its nearest
location's score) and mark the contact point it chose. Its episode runs in evaluate's own env,
policy_env's PrimitiveEnv with the policy inside the diagram, so here too the outcome is
evaluate's for the seed.
"""

from __future__ import annotations

import numpy as np

from corn_drake.contract import POSITION_DIM
from corn_drake.evaluation.episodes import policy_env, run_episode
from corn_drake.rl.envs.teacher_env import TeacherEnv
from corn_drake.viz.attention_view import viridis_rgb
from corn_drake.viz.gallery import (GOAL_COLOUR, POINT_RADIUS_PX, Still, StillCamera, paint,
                                    pick_steps, side_view)

# The primitive policy's chosen contact point: a colour neither viridis nor the goal's red uses.
CONTACT_COLOUR = np.array([255, 0, 255], np.uint8)


def episode_stills(agent, cfg, spec, seed: int, steps_wanted: str = "start,middle,end"
                   ) -> tuple[list[Still], dict]:
    """Runs one episode of `agent` (mean actions) on `spec` in the env of `cfg` (a
    TeacherDiagramConfig) and renders the stills of `steps_wanted` ("start", "middle", "end",
    or step numbers). Returns (stills, episode summary). A contact-primitive agent's episode
    goes to primitive_episode_stills."""
    if getattr(agent, "kind", None) == "primitive":
        return primitive_episode_stills(agent, cfg, spec, seed, steps_wanted)
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
    picks = pick_steps(steps_wanted, len(frames))
    start, goal = env.episode.initial_object_pose[:3], env.episode.goal_pose[:3]
    camera = StillCamera(cfg.scene, spec, *side_view(start, goal))
    stills = []
    for k in picks:
        step, positions, cloud, scores = frames[k]
        image, painted = _painted_still(camera, positions, cloud, viridis_rgb(scores), goal)
        stills.append(Still(step, image, painted))
    return stills, _summary(seed, result)


def _summary(seed: int, result) -> dict:
    return {"seed": seed, "steps": result.steps, "success": result.success,
            "position_error": result.status.get("position_error")}


def _painted_still(camera, positions, cloud, colours, goal, marks=()) -> tuple[np.ndarray, int]:
    """The render of `positions` with the visible cloud points in `colours`, then the goal (red)
    and each (point, colour) of `marks` drawn over everything. Returns (image, points painted)."""
    rgb, depth = camera.render(positions)
    pixels, z = camera.project(cloud)
    image, painted = paint(rgb, depth, pixels, z, colours)
    for point, colour in ((goal, GOAL_COLOUR), *marks):
        pixel, point_z = camera.project(np.asarray(point, float)[None])
        image, _ = paint(image, np.full(depth.shape, np.inf), pixel, point_z, colour[None],
                         radius=2 * POINT_RADIUS_PX)
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


def primitive_episode_stills(agent, cfg, spec, seed: int, steps_wanted: str = "start,middle,end"
                             ) -> tuple[list[Still], dict]:
    """episode_stills for a contact-primitive agent: one episode in evaluate's env (policy_env:
    the policy inside the diagram, one env step per policy period), each still's cloud coloured
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
    picks = pick_steps(steps_wanted, len(frames))
    start, goal = env.episode.initial_object_pose[:3], env.episode.goal_pose[:3]
    camera = StillCamera(cfg.scene, spec, *side_view(start, goal))
    stills = []
    for k in picks:
        step, positions, cloud = frames[k]
        choice = log.shown_at(k)
        marks = [] if choice is None else [(cloud[choice["point"]], CONTACT_COLOUR)]
        image, painted = _painted_still(camera, positions, cloud,
                                        location_colours(cloud, choice), goal, marks)
        stills.append(Still(step, image, painted))
    return stills, {**_summary(seed, result), "primitives": primitives}
