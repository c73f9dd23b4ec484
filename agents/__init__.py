"""Stable-Baselines3 training, evaluation, baseline controllers and the benchmark suite."""
