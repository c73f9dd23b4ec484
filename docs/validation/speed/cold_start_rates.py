"""Step rates of PectoralFish-Averaged-v2 (single env, native vector env at 4096) and CartPole-v1, in one process.

Prints one JSON line, ``{"single", "vector", "cartpole"}`` in steps/s (env-steps/s for the vector env), each the
best of two passes of random actions (20000 single-env steps, 30 batch steps), after a warm-up. For the
cold-start page (``cold-start.md``): run it alternately in two checkouts (``PYTHONPATH=<checkout>``) or with
``PECTORAL_GYM_KERNEL_BUNDLE=0``, each with its own ``NUMBA_CACHE_DIR``, warmed by a first run.
"""

import json
import time

import gymnasium as gym
import numpy as np

import pectoral_gym  # noqa: F401 - registers the ids

ENV_ID = "PectoralFish-Averaged-v2"


def single(env_id: str, n: int = 20000) -> float:
    """Steps/s of one env through ``gymnasium.make``, reset when an episode ends."""
    env = gym.make(env_id)
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (n, 8)).astype(np.float32)
    for action in actions[:500]:  # warm-up
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return n / (time.perf_counter() - start)


def vector(env_id: str, num_envs: int = 4096, steps: int = 30) -> float:
    """Env-steps/s of the native vector env (it resets ended episodes itself)."""
    envs = gym.make_vec(env_id, num_envs, vectorization_mode="vector_entry_point")
    envs.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, num_envs, 8)).astype(np.float32)
    for action in actions[:3]:  # warm-up
        envs.step(action)
    start = time.perf_counter()
    for action in actions:
        envs.step(action)
    return steps * num_envs / (time.perf_counter() - start)


def cartpole(n: int = 20000) -> float:
    """Steps/s of ``CartPole-v1``, the same loop as :func:`single`."""
    env = gym.make("CartPole-v1")
    env.reset(seed=0)
    actions = np.random.default_rng(0).integers(0, 2, n)
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(int(action))
        if terminated or truncated:
            env.reset()
    return n / (time.perf_counter() - start)


if __name__ == "__main__":
    print(json.dumps({"single": max(single(ENV_ID) for _ in range(2)),
                      "vector": max(vector(ENV_ID) for _ in range(2)),
                      "cartpole": max(cartpole() for _ in range(2))}))
