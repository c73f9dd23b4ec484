"""Step-rate benchmark of the fish environments against CartPole.

:func:`run_benchmark` measures, in one process:

* single-env ``step`` rates through :func:`gymnasium.make` for
  ``PectoralFish-Averaged-v0``, ``PectoralFish-Full-v0`` and ``CartPole-v1``,
  all with the same loop: actions pre-generated from the seeded action space,
  ``reset`` on termination or truncation;
* native vector-env rates through ``gymnasium.make_vec(...,
  vectorization_mode="vector_entry_point")`` (averaged at 4096 envs, full at
  1024 envs), in env-steps per second (batch steps x ``num_envs``).

Every measurement is warmed up first (numba compiles, or loads its cache, on
the first call; that time is excluded) and the best of ``repeats`` timed runs
is kept, since noise only ever slows a run down. The result is compared with
the project's targets (:data:`TARGETS`).
"""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["AVERAGED_ID", "CARTPOLE_ID", "FULL_ID", "TARGETS", "VECTOR_ENVS", "run_benchmark"]

AVERAGED_ID = "PectoralFish-Averaged-v0"
FULL_ID = "PectoralFish-Full-v0"
CARTPOLE_ID = "CartPole-v1"
VECTOR_ENVS = {AVERAGED_ID: 4096, FULL_ID: 1024}  # env id -> num_envs

# name -> (threshold, what it is compared with)
TARGETS: dict[str, tuple[float, str]] = {
    "averaged_vs_cartpole": (0.7, "single-env step rate, averaged / CartPole"),
    "full_vs_cartpole": (0.3, "single-env step rate, full / CartPole"),
    "vector_averaged": (2_000_000.0, f"vector env-steps/s, averaged @ {VECTOR_ENVS[AVERAGED_ID]} envs"),
    "vector_full": (100_000.0, f"vector env-steps/s, full @ {VECTOR_ENVS[FULL_ID]} envs"),
}


def _best_rate(run: Callable[[], float], repeats: int) -> float:
    """Best (highest) of ``repeats`` calls of ``run``, each returning a rate."""
    return max(run() for _ in range(max(1, repeats)))


def single_env_rate(env_id: str, steps: int, repeats: int = 3, seed: int = 0) -> float:
    """Steps per second of one env made with :func:`gymnasium.make`.

    Args:
        env_id: Registered environment id.
        steps: Steps per timed run.
        repeats: Timed runs; the best is returned.
        seed: Seeds the action space (actions are pre-generated) and the first reset.

    Returns:
        The best ``steps / elapsed`` over the repeats [steps/s].
    """
    import gymnasium as gym

    env = gym.make(env_id)
    try:
        env.action_space.seed(seed)
        actions = [env.action_space.sample() for _ in range(steps)]

        def run(n: int = steps) -> float:
            batch = actions[:n]
            env.reset(seed=seed)
            start = time.perf_counter()
            for action in batch:
                _, _, terminated, truncated, _ = env.step(action)
                if terminated or truncated:
                    env.reset()
            return n / (time.perf_counter() - start)

        run(min(steps, 100))  # warm-up: compilation, caches
        return _best_rate(run, repeats)
    finally:
        env.close()


def vector_env_rate(env_id: str, num_envs: int, steps: int, repeats: int = 3, seed: int = 0) -> float:
    """Env-steps per second of a native vector env (``vectorization_mode="vector_entry_point"``).

    Args:
        env_id: Registered environment id with a ``vector_entry_point``.
        num_envs: Number of sub-environments.
        steps: Batch steps per timed run.
        repeats: Timed runs; the best is returned.
        seed: Seeds the action space (actions are pre-generated) and the first reset.

    Returns:
        The best ``steps * num_envs / elapsed`` over the repeats [env-steps/s].
    """
    import gymnasium as gym

    envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point")
    try:
        envs.action_space.seed(seed)
        actions = [envs.action_space.sample() for _ in range(steps)]

        def run() -> float:
            envs.reset(seed=seed)
            start = time.perf_counter()
            for action in actions:
                envs.step(action)  # the vector env autoresets
            return steps * num_envs / (time.perf_counter() - start)

        envs.reset(seed=seed)  # warm-up: compilation, thread pool start-up
        for action in actions[:2]:
            envs.step(action)
        return _best_rate(run, repeats)
    finally:
        envs.close()


def _environment() -> dict[str, Any]:
    """Versions and hardware that the rates depend on."""
    import gymnasium as gym
    import numba

    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "gymnasium": gym.__version__,
        "cpu_count": os.cpu_count(),
        "numba_threads": numba.get_num_threads(),
        "machine": platform.machine(),
    }


def run_benchmark(
    steps: int = 20_000,
    vector_steps: int = 100,
    repeats: int = 3,
    seed: int = 0,
    quick: bool = False,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Measure all step rates and compare them with :data:`TARGETS`.

    Args:
        steps: Single-env steps per timed run.
        vector_steps: Vector-env batch steps per timed run.
        repeats: Timed runs per measurement (best kept).
        seed: Seed of the pre-generated actions and of the resets.
        quick: Smoke-test sizes (300 single steps, 3 vector steps, 1 repeat);
            the numbers are then too noisy to judge the targets.
        progress: Called with a short message before each measurement.

    Returns:
        A JSON-ready dict with keys ``single_env`` (steps/s per env id),
        ``vector_env`` (env-steps/s per env id), ``num_envs`` (per vector env
        id), ``ratios`` (``averaged_vs_cartpole``, ``full_vs_cartpole``),
        ``targets`` (per target: ``target``, ``value``, ``met``, ``what``),
        ``all_met``, ``errors`` (env id -> message for a measurement that
        could not run; its rate is ``None``), ``settings`` and ``environment``.
    """
    import pectoral_gym  # noqa: F401  (registers the fish envs)

    if quick:
        steps, vector_steps, repeats = min(steps, 300), min(vector_steps, 3), 1
    if steps < 1 or vector_steps < 1 or repeats < 1:
        raise ValueError(f"steps, vector_steps and repeats must be >= 1, got {steps}, {vector_steps}, {repeats}")
    say = progress or (lambda _msg: None)
    errors: dict[str, str] = {}

    def attempt(key: str, measure: Callable[[], float]) -> float | None:
        try:
            return measure()
        except Exception as exc:  # noqa: BLE001 - reported in the result, not fatal for the others
            errors[key] = f"{type(exc).__name__}: {exc}"
            return None

    single: dict[str, float | None] = {}
    for env_id in (AVERAGED_ID, FULL_ID, CARTPOLE_ID):
        say(f"single env {env_id}: {repeats} x {steps} steps")
        single[env_id] = attempt(env_id, lambda e=env_id: single_env_rate(e, steps, repeats, seed))
    vector: dict[str, float | None] = {}
    for env_id, num_envs in VECTOR_ENVS.items():
        say(f"vector env {env_id} @ {num_envs}: {repeats} x {vector_steps} steps")
        vector[env_id] = attempt(
            f"vector:{env_id}", lambda e=env_id, n=num_envs: vector_env_rate(e, n, vector_steps, repeats, seed)
        )

    def ratio(a: float | None, b: float | None) -> float | None:
        return a / b if a is not None and b else None

    ratios = {
        "averaged_vs_cartpole": ratio(single[AVERAGED_ID], single[CARTPOLE_ID]),
        "full_vs_cartpole": ratio(single[FULL_ID], single[CARTPOLE_ID]),
    }
    values = {**ratios, "vector_averaged": vector[AVERAGED_ID], "vector_full": vector[FULL_ID]}
    targets = {
        name: {"target": threshold, "value": values[name],
               "met": values[name] is not None and values[name] >= threshold, "what": what}
        for name, (threshold, what) in TARGETS.items()
    }
    return {
        "single_env": single,
        "vector_env": vector,
        "num_envs": dict(VECTOR_ENVS),
        "ratios": ratios,
        "targets": targets,
        "all_met": all(t["met"] for t in targets.values()),
        "errors": errors,
        "settings": {"steps": steps, "vector_steps": vector_steps, "repeats": repeats, "seed": seed, "quick": quick},
        "environment": _environment(),
    }
