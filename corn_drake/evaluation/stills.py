"""Gallery stills of one episode: a teacher's episode run by evaluate's own episode runner (so
the outcome is the one evaluate reports for the seed), and the steps asked for rendered by
viz/gallery.py's camera with the cloud painted by the policy's attention.
"""

from __future__ import annotations

import numpy as np

from corn_drake.contract import POSITION_DIM
from corn_drake.evaluation.episodes import run_episode
from corn_drake.rl.env import TeacherEnv
from corn_drake.viz.attention_view import viridis_rgb
from corn_drake.viz.gallery import (GOAL_COLOUR, POINT_RADIUS_PX, Still, StillCamera, paint,
                                    pick_steps, side_view)


def episode_stills(agent, cfg, spec, seed: int, steps_wanted: str = "start,middle,end"
                   ) -> tuple[list[Still], dict]:
    """Runs one episode of `agent` (mean actions) on `spec` in the env of `cfg` (a
    TeacherDiagramConfig) and renders the stills of `steps_wanted` ("start", "middle", "end",
    or step numbers). Returns (stills, episode summary)."""
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
        rgb, depth = camera.render(positions)
        pixels, z = camera.project(cloud)
        image, painted = paint(rgb, depth, pixels, z, viridis_rgb(scores))
        goal_pixel, goal_z = camera.project(goal[None])
        image, _ = paint(image, np.full(depth.shape, np.inf), goal_pixel, goal_z,
                         GOAL_COLOUR[None], radius=2 * POINT_RADIUS_PX)  # drawn over everything
        stills.append(Still(step, image, painted))
    summary = {"seed": seed, "steps": result.steps, "success": result.success,
               "position_error": result.status.get("position_error")}
    return stills, summary
