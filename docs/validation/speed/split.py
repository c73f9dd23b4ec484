"""Where the averaged vector env's time goes: the whole env step against the model's command + advance.

``python docs/validation/speed/split.py`` (run it in each checkout to compare, e.g. with
``PYTHONPATH=<worktree>``). 4096 envs, 100 batch steps of random actions (new every step), best of 5;
the model alone gets seeded patterns from the envs' action ranges, new every 0.5 s.
"""

import time
from functools import partial

import gymnasium as gym
import numpy as np

import pectoral_gym  # noqa: F401 - registers the ids
from pectoral_gym.model.models import AveragedModel
from pectoral_gym.scaling.validation.fidelity import draw_patterns

N, STEPS = 4096, 100


def best(run, repeats: int = 5) -> float:
    """Shortest of ``repeats`` wall times of ``run()`` [s]."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def steps_of_env(env, actions) -> None:
    """One batch step per row of ``actions``."""
    for a in actions:
        env.step(a)


def steps_of_model(model, commands) -> None:
    """``command_array`` + ``advance(0.5)`` per command."""
    for c in commands:
        model.command_array(c)
        model.advance(0.5)


for settings in ({}, {"transitions": True, "observe_fins": True}):
    env = gym.make_vec("PectoralFish-Averaged-v0", num_envs=N, vectorization_mode="vector_entry_point", **settings)
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (STEPS, *env.action_space.shape)).astype(np.float32)
    model = AveragedModel(N, transitions=settings.get("transitions", False), ripple_offsets=False)
    model.reset()
    patterns = draw_patterns(np.random.default_rng(1), N, STEPS)
    commands = [np.ascontiguousarray(patterns[:, k]) for k in range(STEPS)]
    run_env = partial(steps_of_env, env, actions)
    run_model = partial(steps_of_model, model, commands)
    run_env(), run_model()  # compile or load numba's cache
    t_env, t_model = best(run_env), best(run_model)
    print(f"{settings or 'default'}: env {STEPS * N / t_env / 1e3:.0f}k env-steps/s, model command + advance "
          f"{STEPS * N / t_model / 1e3:.0f}k fish-steps/s ({t_model / t_env:.0%} of the env's time)")
