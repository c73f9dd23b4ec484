"""Time of the averaged model's RK4 substeps alone, against the env step they sit in.

``python docs/validation/speed/rk4_share.py [NUM_ENVS] [SUBSTEPS]`` (defaults 4096 and 7.11, the substeps per
env step that ``count_steps.py`` measures for ``PectoralFish-Averaged-v2``). The env is stepped 20 times with
random actions; then its fish's states, coefficients and cached forcing are copied and ``stepping._rk4``
(with the step control of ``_stable_step``) runs over them, one core, ``h = 0.5 / SUBSTEPS`` s, the yaw
oscillation taken from each fish's cache as the segment would; best of 7 over 20 substeps per fish. Prints
ns per substep and the time of ``SUBSTEPS`` substeps for every fish of a batch, beside the env's own batch
step (native vector env, both cores, best of 7 passes of 20 steps: wall time and the process's CPU time), and
the bytes of the per-env arrays of the model and the env core.
"""

import sys
import time

import gymnasium as gym
import numpy as np
from numba import njit

import pectoral_gym  # noqa: F401 - registers the ids
from pectoral_gym.model import forcing_cache as fc
from pectoral_gym.model.dynamics import Forcing, rate_constants
from pectoral_gym.model.params import BodyCoefficients, Coef
from pectoral_gym.model.stepping import _rk4, _stable_step

n = int(sys.argv[1]) if len(sys.argv) > 1 else 4096
substeps = float(sys.argv[2]) if len(sys.argv) > 2 else 7.11
ROUNDS = 20


@njit
def substeps_of(state, integral, coef, forcing, osc, h, rounds):
    """``rounds`` RK4 substeps of every fish with the averaged model's step control (its result unused)."""
    total = 0.0
    for i in range(state.shape[0]):
        body = BodyCoefficients(coef[i, Coef.M1], coef[i, Coef.M2], coef[i, Coef.J3],
                                coef[i, Coef.C1], coef[i, Coef.C2], coef[i, Coef.C4])
        rates = rate_constants(body.m1, body.m2, body.J3, body.c1, body.c2, body.c4)
        f = Forcing(forcing[i, 0], forcing[i, 1], forcing[i, 2])
        for _ in range(rounds):
            total += _stable_step(state, i, rates, 0.0, 0.0, osc[i], 0.25)
            _rk4(state, integral, i, h, f, f, f, body, osc[i])
    return total


envs = gym.make_vec("PectoralFish-Averaged-v2", num_envs=n, vectorization_mode="vector_entry_point")
envs.action_space.seed(0)
actions = [envs.action_space.sample() for _ in range(20)]
envs.reset(seed=0)
for a in actions:
    envs.step(a)
model = envs.unwrapped.core.model
cache = model.forcing_cache
forcing = np.stack([cache[:, :, k].sum(axis=1) + cache[:, :, t].sum(axis=1)
                    for k, t in ((fc.AVG_FX, fc.TR_FX), (fc.AVG_FY, fc.TR_FY), (fc.AVG_TAU, fc.TR_TAU))], axis=1)
# the yaw oscillation with both fins at beat phase 0: a typical size (the branch taken is what counts)
osc = np.hypot(cache[:, :, fc.OSC_COS].sum(axis=1), cache[:, :, fc.OSC_SIN].sum(axis=1))
start_state, start_integral, coef = model.state.copy(), model.integral.copy(), model.coef.copy()
h = 0.5 / substeps
substeps_of(start_state.copy(), start_integral.copy(), coef, forcing, osc, h, 1)  # compile
best = np.inf
for _ in range(7):
    state, integral = start_state.copy(), start_integral.copy()
    t0 = time.perf_counter()
    substeps_of(state, integral, coef, forcing, osc, h, ROUNDS)
    best = min(best, time.perf_counter() - t0)
per_substep = best / (n * ROUNDS)
env_best = env_cpu = np.inf
for _ in range(7):
    envs.reset(seed=0)
    t0, c0 = time.perf_counter(), time.process_time()
    for a in actions:
        envs.step(a)
    env_best = min(env_best, (time.perf_counter() - t0) / len(actions))
    env_cpu = min(env_cpu, (time.process_time() - c0) / len(actions))  # both threads' CPU, whatever the load
per_env = [a for a in (*vars(model).values(), *vars(envs.unwrapped.core).values())
           if isinstance(a, np.ndarray) and a.shape[:1] == (n,)]
print(f"arrays of one env (model and env core): {sum(a.nbytes for a in per_env) // n} bytes")
print(f"RK4 substep with step control: {per_substep * 1e9:.0f} ns (one core); {substeps} per env step for "
      f"{n} fish: {per_substep * substeps * n * 1e3:.2f} ms of one core")
print(f"env batch step @ {n}: {env_best * 1e3:.2f} ms on 2 cores ({n / env_best / 1e6:.3f} M env-steps/s), "
      f"{env_cpu * 1e3:.2f} ms of CPU (RK4 substeps: {per_substep * substeps * n / env_cpu:.0%} of it)")
