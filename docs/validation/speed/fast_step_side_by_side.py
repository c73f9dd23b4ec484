"""The native vector env of ``PectoralFish-Averaged-v2`` with the averaged model's ``fast_step`` off and on, one run.

``python docs/validation/speed/fast_step_side_by_side.py [NUM_ENVS] [STEPS] [REPEATS]`` (defaults 4096, 30, 7):
``gym.make_vec(..., vectorization_mode="vector_entry_point")``, seeded random actions (new every step,
pre-generated, as ``python -m pectoral_gym.tools.peer_table`` steps it). Passes alternate off, on, off, on,
...; each pass resets (seed 0) and steps ``STEPS`` times. Prints the best pass of each in wall time
(M env-steps/s) and in the process's CPU time per env step (both threads; independent of other jobs'
load), the largest difference of the observations after the last pass of each (the option reaches the
env's kernel: they differ), and whether each mode's first and last passes (same seeds) end bit for bit equal.
"""

import sys
import time

import gymnasium as gym
import numpy as np

import pectoral_gym  # noqa: F401 - registers the ids

n = int(sys.argv[1]) if len(sys.argv) > 1 else 4096
steps = int(sys.argv[2]) if len(sys.argv) > 2 else 30
repeats = int(sys.argv[3]) if len(sys.argv) > 3 else 7
envs = gym.make_vec("PectoralFish-Averaged-v2", num_envs=n, vectorization_mode="vector_entry_point")
envs.action_space.seed(0)
actions = [envs.action_space.sample() for _ in range(steps)]
model = envs.unwrapped.core.model


def one_pass(fast: bool):
    """Wall and CPU time [s] of one pass with the option ``fast``, and the last observations."""
    model.fast_step = fast
    envs.reset(seed=0)
    t0, c0 = time.perf_counter(), time.process_time()
    for a in actions:
        obs, *_ = envs.step(a)
    return time.perf_counter() - t0, time.process_time() - c0, obs.copy()


first = {fast: one_pass(fast)[2] for fast in (False, True)}  # compiles (a run-time argument of the same kernel)
best = {False: (np.inf, np.inf), True: (np.inf, np.inf)}
last = {}
for _ in range(repeats):
    for fast in (False, True):
        wall, cpu, last[fast] = one_pass(fast)
        best[fast] = (min(best[fast][0], wall), min(best[fast][1], cpu))
model.fast_step = False
print(f"PectoralFish-Averaged-v2, native vector env @ {n}, {steps} steps per pass, best of {repeats}")
for fast, (wall, cpu) in best.items():
    print(f"fast_step={fast!s:5}: {n * steps / wall / 1e6:.3f} M env-steps/s wall, "
          f"{cpu / (n * steps) * 1e6:.3f} us CPU per env step")
print(f"speed-up: wall {best[False][0] / best[True][0]:.2f}x, CPU {best[False][1] / best[True][1]:.2f}x; "
      f"observations after {steps} steps differ by up to {np.max(np.abs(last[True] - last[False])):.3g}")
print("the same seeded pass repeats bit for bit: "
      f"off {np.array_equal(first[False], last[False])}, on {np.array_equal(first[True], last[True])}")
