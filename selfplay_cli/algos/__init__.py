"""Learners: each one file that reads top to bottom (PPO, DQN)."""
