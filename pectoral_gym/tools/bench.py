"""Step-rate benchmark of the fish environments against CartPole.

:func:`run_benchmark` measures, in one process:

* single-env ``step`` rates through :func:`gymnasium.make` for
  ``PectoralFish-Averaged-v0``, ``PectoralFish-Full-v0`` and ``CartPole-v1``,
  all with the same loop: actions pre-generated from the seeded action space,
  ``reset`` on termination or truncation;
* native vector-env rates through ``gymnasium.make_vec(...,
  vectorization_mode="vector_entry_point")`` (averaged at 4096 envs, full at
  1024 envs, the averaged env with the shipped PPO file's settings,
  :data:`TRAINING_SETTINGS`, and the full env with its fast integration preset,
  :data:`FAST_SETTINGS`, at 4096 envs beside the averaged one), in env-steps per
  second (batch steps x ``num_envs``).

Every action is drawn afresh, so the fins change pattern at every step, as under
a learning agent. ``pectoral-fish step-rate --against DIR`` runs the same benchmark
in another checkout, alternating with this one (:mod:`pectoral_gym.tools.bench_compare`);
:mod:`pectoral_gym.tools.peer_table` uses the same timers for the table of the fish beside
CartPole and MuJoCo's Swimmer.

Every measurement is warmed up first (numba compiles, or loads its cache, on
the first call; that time is excluded) and the best of ``repeats`` timed runs
is kept, since noise only ever slows a run down. The repeats go round robin
over all seven measurements, so a burst of load from elsewhere on the machine
slows CartPole and the fish envs alike instead of skewing one ratio. The result is compared with
the project's targets (:data:`TARGETS`).
"""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable
from functools import partial
from typing import Any, NamedTuple

import numpy as np

from pectoral_gym.versions import SIMULATION_IDS

__all__ = [
    "AVERAGED_ID", "CARTPOLE_ID", "FAST_SETTINGS", "FULL_ID", "SINGLE_ENVS", "TARGETS", "TRAINING_SETTINGS",
    "VECTOR_ENVS",
    "run_benchmark", "single_env_timer", "vector_env_timer",
]

# The simulation-only ids: the recorded throughput figures (docs/validation/speed) were measured on them.
AVERAGED_ID = SIMULATION_IDS["averaged"]
FULL_ID = SIMULATION_IDS["full"]
CARTPOLE_ID = "CartPole-v1"
SINGLE_ENVS = (AVERAGED_ID, FULL_ID, CARTPOLE_ID)
VECTOR_ENVS = {AVERAGED_ID: 4096, FULL_ID: 1024}  # env id -> num_envs
#: The averaged env as agents/hyperparams/ppo.yml trains on it (its ``env_kwargs``), measured at 4096 envs too.
TRAINING_SETTINGS = {"transitions": True, "observe_fins": True}
TRAINING_KEY = f"{AVERAGED_ID} (PPO settings)"
#: The full env with the fast integration preset (``pectoral_gym.model.models.FULL_INTEGRATION``), at the averaged
#: env's size.
FAST_SETTINGS = {"integration": "fast"}
FAST_KEY = f"{FULL_ID} (fast integration)"

# name -> (threshold, what it is compared with)
TARGETS: dict[str, tuple[float, str]] = {
    "averaged_vs_cartpole": (0.7, "single-env step rate, averaged / CartPole"),
    "full_vs_cartpole": (0.3, "single-env step rate, full / CartPole"),
    "vector_averaged": (2_000_000.0, f"vector env-steps/s, averaged @ {VECTOR_ENVS[AVERAGED_ID]} envs"),
    "vector_full": (100_000.0, f"vector env-steps/s, full @ {VECTOR_ENVS[FULL_ID]} envs"),
}


class _Timer(NamedTuple):
    """One warmed-up measurement: ``run()`` times one pass and returns its rate; ``close()`` frees the env."""

    run: Callable[[], float]
    close: Callable[[], None]


def single_env_timer(env_id: str, steps: int, seed: int = 0) -> _Timer:
    """Warmed-up timer of ``steps`` single-env steps through :func:`gymnasium.make`.

    Actions are pre-generated from the seeded action space; the env is reset
    (seeded) before each pass and again on termination or truncation.

    Args:
        env_id: Registered environment id.
        steps: Steps per timed pass.
        seed: Seeds the action space and the first reset of each pass.

    Returns:
        A timer whose ``run()`` gives ``steps / elapsed`` [steps/s].
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

        run(min(steps, 100))  # warm-up: numba compilation or cache load, first-call caches
    except BaseException:
        env.close()
        raise
    return _Timer(run, env.close)


def vector_env_timer(env_id: str, num_envs: int, steps: int, seed: int = 0,
                     env_kwargs: dict[str, Any] | None = None, mode: str = "vector_entry_point") -> _Timer:
    """Warmed-up timer of ``steps`` batch steps of a vector env.

    The env comes from ``gymnasium.make_vec(env_id, num_envs=num_envs,
    vectorization_mode=mode)`` (by default the env's native vector env;
    ``"sync"`` for a :class:`gymnasium.vector.SyncVectorEnv` of single envs)
    and autoresets by itself.

    Args:
        env_id: Registered environment id with a ``vector_entry_point``.
        num_envs: Number of sub-environments.
        steps: Batch steps per timed pass.
        seed: Seeds the action space and the reset before each pass.
        env_kwargs: Passed to the env (e.g. :data:`TRAINING_SETTINGS`).
        mode: Gymnasium's ``vectorization_mode``.

    Returns:
        A timer whose ``run()`` gives ``steps * num_envs / elapsed`` [env-steps/s].
    """
    import gymnasium as gym

    envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode=mode, **(env_kwargs or {}))
    try:
        envs.action_space.seed(seed)
        actions = [envs.action_space.sample() for _ in range(steps)]

        def run(n: int = steps) -> float:
            batch = actions[:n]
            envs.reset(seed=seed)
            start = time.perf_counter()
            for action in batch:
                envs.step(action)
            return n * num_envs / (time.perf_counter() - start)

        run(min(steps, 3))  # warm-up: compilation, thread-pool start-up
    except BaseException:
        envs.close()
        raise
    return _Timer(run, envs.close)


def _environment() -> dict[str, Any]:
    """Versions, hardware and thread settings that the rates depend on."""
    import gymnasium as gym
    import numba

    try:
        layer = numba.threading_layer()
    except ValueError:  # no parallel kernel has run
        layer = None
    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "gymnasium": gym.__version__,
        "cpu_count": os.cpu_count(),
        "numba_threads": numba.get_num_threads(),
        "numba_threading_layer": layer,
        "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY"),  # the user's; unset: the envs start threads passive
        "machine": platform.machine(),
    }


def run_benchmark(
    steps: int = 20_000,
    vector_steps: int = 100,
    repeats: int = 5,
    seed: int = 0,
    quick: bool = False,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Measure all step rates and compare them with :data:`TARGETS`.

    Args:
        steps: Single-env steps per timed pass.
        vector_steps: Vector-env batch steps per timed pass.
        repeats: Timed passes per measurement, round robin (best kept).
        seed: Seed of the pre-generated actions and of the resets.
        quick: Smoke-test sizes (300 single steps, 3 vector steps, 1 repeat);
            the numbers are then too noisy to judge the targets.
        progress: Called with a short message before the warm-up and each repeat.

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

    def attempt(key: str, measure: Callable[[], Any]) -> Any:
        try:
            return measure()
        except Exception as exc:  # noqa: BLE001 - reported in the result, not fatal for the others
            errors[key] = f"{type(exc).__name__}: {exc}"
            return None

    say("warming up (numba compilation or cache load) ...")
    makers: dict[str, Callable[[], _Timer]] = {e: partial(single_env_timer, e, steps, seed) for e in SINGLE_ENVS}
    makers.update({f"vector:{e}": partial(vector_env_timer, e, n, vector_steps, seed) for e, n in VECTOR_ENVS.items()})
    makers[f"vector:{TRAINING_KEY}"] = partial(vector_env_timer, AVERAGED_ID, VECTOR_ENVS[AVERAGED_ID], vector_steps,
                                               seed, TRAINING_SETTINGS)
    makers[f"vector:{FAST_KEY}"] = partial(vector_env_timer, FULL_ID, VECTOR_ENVS[AVERAGED_ID], vector_steps, seed,
                                           FAST_SETTINGS)
    timers: dict[str, _Timer] = {}
    for key, make in makers.items():
        timer = attempt(key, make)
        if timer is not None:
            timers[key] = timer
    # Round robin: every repeat times each env once, so a burst of load elsewhere hits all of them alike.
    best: dict[str, float] = {}
    try:
        for rep in range(repeats):
            say(f"repeat {rep + 1}/{repeats}: {steps} single-env steps, {vector_steps} vector steps per env")
            for key, timer in list(timers.items()):
                rate = attempt(key, timer.run)
                if rate is None:
                    timers.pop(key).close()
                else:
                    best[key] = max(best.get(key, 0.0), rate)
    finally:
        for timer in timers.values():
            timer.close()
    single = {env_id: best.get(env_id) for env_id in SINGLE_ENVS}
    vector = {env_id: best.get(f"vector:{env_id}") for env_id in (*VECTOR_ENVS, TRAINING_KEY, FAST_KEY)}

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
        "num_envs": {**VECTOR_ENVS, TRAINING_KEY: VECTOR_ENVS[AVERAGED_ID], FAST_KEY: VECTOR_ENVS[AVERAGED_ID]},
        "ratios": ratios,
        "targets": targets,
        "all_met": all(t["met"] for t in targets.values()),
        "errors": errors,
        "settings": {"steps": steps, "vector_steps": vector_steps, "repeats": repeats, "seed": seed, "quick": quick},
        "environment": _environment(),
    }
