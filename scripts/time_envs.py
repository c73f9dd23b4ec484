"""Step rates of the fish environments against CartPole-v1 (a timing script, not a test).

Usage: ``python scripts/time_envs.py [--steps 20000] [--vector]``
"""

from __future__ import annotations

import argparse
import time
import timeit

import gymnasium as gym
import numpy as np

import pectoral_gym  # noqa: F401  (registers the ids)
from pectoral_gym.envs.vector import PectoralFishVectorEnv
from pectoral_gym.registration import register_envs


def single_us(env_id: str, steps: int, **kwargs) -> float:
    """Best-of-3 µs per ``env.step`` through ``gym.make`` (resets included when episodes end)."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(256)]

    def run():
        for k in range(steps):
            _, _, terminated, truncated, _ = env.step(actions[k & 255])
            if terminated or truncated:
                env.reset()

    run()
    return min(timeit.repeat(run, number=1, repeat=5)) / steps * 1e6


def vector_rate(model: str, num_envs: int, steps: int) -> tuple[float, float]:
    """Env-steps per second of the native vector env, and fish-steps per second of ``model.advance`` alone."""
    env = PectoralFishVectorEnv(num_envs, model=model)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (8, num_envs, 8)).astype(np.float32)
    for k in range(5):
        env.step(actions[k & 7])
    t0 = time.perf_counter()
    for k in range(steps):
        env.step(actions[k & 7])
    rate = num_envs * steps / (time.perf_counter() - t0)
    fish = env.core.model
    t0 = time.perf_counter()
    for _ in range(steps):
        fish.advance(env.config.control_period)
    return rate, num_envs * steps / (time.perf_counter() - t0)


def main() -> None:
    """Print the step rates."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--vector", action="store_true", help="also time the vector env")
    args = parser.parse_args()
    register_envs()
    for env_id in ("PectoralFish-Averaged-v0", "PectoralFish-Full-v0"):
        for task in ("goal", "track"):
            cart = single_us("CartPole-v1", args.steps)  # measured next to each env: the machine may be shared
            us = single_us(env_id, args.steps, task=task)
            print(f"{env_id:25s} {task:5s} {us:6.2f} us/step, CartPole-v1 {cart:5.2f} us/step "
                  f"({cart / us:.2f}x CartPole rate)")
    if args.vector:
        for model, n in (("averaged", 4096), ("full", 1024)):
            rate, ceiling = vector_rate(model, n, 200)
            print(f"vector {model:8s} {n:5d} envs: {rate:,.0f} env-steps/s "
                  f"(model.advance alone: {ceiling:,.0f} fish-steps/s)")


if __name__ == "__main__":
    main()
