"""The episode benchmarks: env and planner steps/s against bare physics of the same motions
(teacher, student, library objects, contact primitives, the 6D expert)."""
