"""Where the averaged vector env's time goes: the whole env step against the model's command + advance.

``python docs/validation/speed/split.py`` (run it in each checkout to compare, e.g. with
``PYTHONPATH=<worktree>``). 4096 envs, 100 batch steps of random actions (new every step), best of 5;
the model alone gets seeded patterns from the envs' action ranges, new every 0.5 s.
"""

import time

import gymnasium as gym
import numpy as np

import pectoral_gym  # noqa: F401 - registers the ids
from pectoral_gym.models import AveragedModel
from scaling.fidelity import draw_patterns

N, STEPS = 4096, 100


def best(run, repeats: int = 5) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


for settings in ({}, {"transitions": True, "observe_fins": True}):
    env = gym.make_vec("PectoralFish-Averaged-v0", num_envs=N, vectorization_mode="vector_entry_point", **settings)
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (STEPS, *env.action_space.shape)).astype(np.float32)

    def run_env():
        for a in actions:
            env.step(a)

    model = AveragedModel(N, transitions=settings.get("transitions", False), ripple_offsets=False)
    model.reset()
    patterns = draw_patterns(np.random.default_rng(1), N, STEPS)
    commands = [np.ascontiguousarray(patterns[:, k]) for k in range(STEPS)]

    def run_model():
        for c in commands:
            model.command_array(c)
            model.advance(0.5)

    run_env(), run_model()  # compile or load numba's cache
    t_env, t_model = best(run_env), best(run_model)
    print(f"{settings or 'default'}: env {STEPS * N / t_env / 1e3:.0f}k env-steps/s, model command + advance "
          f"{STEPS * N / t_model / 1e3:.0f}k fish-steps/s ({t_model / t_env:.0%} of the env's time)")
