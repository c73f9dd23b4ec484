"""Stable-Baselines3 training and evaluation: configs, policies, the vector adapter, metrics and results, the demo."""
