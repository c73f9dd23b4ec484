"""Time the batch steps of one native vector env; prints JSON: each pass's rate and each step's time.

``python vector_steps.py ENV_ID NUM_ENVS STEPS PASSES [ENV_KWARGS_JSON]``, run by side_by_side.py with
``PYTHONPATH`` set to the checkout under test. Seeded random actions, new every step; reset before each pass.
"""

import json
import sys
import time
import warnings

import gymnasium as gym
import numpy as np

import pectoral_gym  # noqa: F401  (registers the envs)

warnings.filterwarnings("ignore")
env_id, n, steps, passes = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
kwargs = json.loads(sys.argv[5]) if len(sys.argv) > 5 else {}
envs = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **kwargs)
envs.action_space.seed(0)
actions = [envs.action_space.sample() for _ in range(steps)]
envs.reset(seed=0)
for a in actions[:3]:  # warm-up: compilation or cache load, thread start
    envs.step(a)
times = np.zeros((passes, steps))
for p in range(passes):
    envs.reset(seed=0)
    for t, a in enumerate(actions):
        start = time.perf_counter()
        envs.step(a)
        times[p, t] = time.perf_counter() - start
print(json.dumps({"rates": (steps * n / times.sum(axis=1)).tolist(), "steps": times.tolist()}))
