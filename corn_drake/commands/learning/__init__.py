"""The commands that train: contact pretraining, the teacher (PPO or contact primitives), the
DAgger student, and the outcome and value choosers fitted to data."""
