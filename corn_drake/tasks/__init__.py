"""Tasks: how an episode's start and goal are drawn for what the task asks of the robot.

sampling.py  robot joints, object start and goal per goal variant; raises when ranges cannot be met
episode.py   Episode (one reset's draws) and sample_episode, used by every diagram's reset

The task's config and its goal variants (tagged `task.goal`) are config/task.py's.
"""
