"""RK4 substeps, segments, latches, refreshes and corrections of the averaged model per env step, in the env.

Needs a checkout with ``count_steps.patch`` applied (it counts into six extra forcing-cache fields of
fin 0; see README.md here). Corrections: latches onto a transitional half-stroke (one that does not
start at its pattern's turning point: ``_transition``'s mean forces and the oscillation gain's
quadrature run), and recovery strokes after a power stroke of another pattern (the power-stroke excesses).

``python count_steps.py [ENV_ID] [NUM_ENVS] [STEPS]`` (defaults
``PectoralFish-Averaged-v2``, 4096, 60): the native vector env with seeded random actions, new every
step, as ``python -m pectoral_gym.tools.peer_table`` steps it; after each step the counters are summed
and zeroed (an env that resets clears its row, so nothing is counted twice or lost but the reset's).
"""

import sys

import gymnasium as gym
import numpy as np

import pectoral_gym  # noqa: F401 - registers the ids
from pectoral_gym.model import forcing_cache as fc

env_id = sys.argv[1] if len(sys.argv) > 1 else "PectoralFish-Averaged-v2"
n = int(sys.argv[2]) if len(sys.argv) > 2 else 4096
steps = int(sys.argv[3]) if len(sys.argv) > 3 else 60
envs = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
envs.action_space.seed(0)
actions = [envs.action_space.sample() for _ in range(steps)]
envs.reset(seed=0)
cache = envs.unwrapped.core.model.forcing_cache
fields = slice(fc.N_RK4, fc.N_EXCESS + 1)
cache[:, 0, fields] = 0.0
total = np.zeros(6)
for a in actions:
    envs.step(a)
    total += cache[:, 0, fields].sum(axis=0)
    cache[:, 0, fields] = 0.0
rk4, segments, latches, refreshes, transitional, excess = total / (n * steps)
print(f"{env_id} @ {n} envs, per env step: RK4 steps {rk4:.2f}, segments {segments:.2f}, "
      f"latches {latches:.2f}, forcing refreshes {refreshes:.2f}, transitional latches {transitional:.2f}, "
      f"power-stroke excesses {excess:.2f}")
