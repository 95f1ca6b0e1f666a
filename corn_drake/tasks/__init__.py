"""Tasks: what an episode asks of the robot, and how its start and goal are drawn.

specs.py     the goal variants (one tagged `task.goal` in TaskConfig) — no imports from config
sampling.py  robot joints, object start and goal per variant; raises when ranges cannot be met
episode.py   Episode (one reset's draws) and sample_episode, used by every diagram's reset

This file imports nothing: corn_drake.config imports tasks.specs, and sampling imports config.
"""
