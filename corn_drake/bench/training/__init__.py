"""The training benchmarks: the real trainers' steps/s against bare physics, over Ray
worker counts, per policy, per PPO update, and what the cores themselves allow."""
