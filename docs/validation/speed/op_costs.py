"""Cost [ns and cycles at the nominal clock] of the scalar operations of the averaged step, compiled by numba.

``python docs/validation/speed/op_costs.py [GHZ]`` (default 2.1, the nominal clock of /proc/cpuinfo). Each
operation runs over 2**20 independent inputs (no dependency between calls: a throughput, the best case
for the averaged step's per-fish loop), not vectorised (numba's loop and SLP vectorisers are off:
the kernels are scalar per fish), best of 7; one core. The loop's own load, store and add are
included, so the cheap operations read high; "add+mul (loop)" is that floor.
"""

import math
import os
import sys
import time

os.environ["NUMBA_LOOP_VECTORIZE"] = "0"  # scalar, as in the per-fish kernels (before numba is imported)
os.environ["NUMBA_SLP_VECTORIZE"] = "0"

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

GHZ = float(sys.argv[1]) if len(sys.argv) > 1 else 2.1
N = 1 << 20


def kernel(op):
    """A compiled loop ``out[k] = op(a[k], b[k])`` over the inputs."""
    @njit(fastmath=False)
    def run(a, b, out):
        for k in range(a.size):
            out[k] = op(a[k], b[k])
    return run


OPS = {
    "add+mul (loop)": njit(lambda x, y: x * y + y),
    "divide": njit(lambda x, y: x / y),
    "sqrt": njit(lambda x, y: math.sqrt(x)),
    "sin": njit(lambda x, y: math.sin(x)),
    "cos": njit(lambda x, y: math.cos(x)),
    "atan2": njit(lambda x, y: math.atan2(x, y)),
    "asin": njit(lambda x, y: math.asin(x)),
    "hypot": njit(lambda x, y: math.hypot(x, y)),
}
rng = np.random.default_rng(0)
a, b = rng.uniform(-0.99, 0.99, N), rng.uniform(0.5, 2.0, N)  # asin's domain; a divisor away from 0
out = np.empty(N)
for name, op in OPS.items():
    run = kernel(op)
    run(a, b, out)  # compile
    best = math.inf
    for _ in range(7):
        start = time.perf_counter()
        run(a, b, out)
        best = min(best, time.perf_counter() - start)
    ns = best / N * 1e9
    print(f"{name:16s} {ns:6.2f} ns  {ns * GHZ:6.1f} cycles")
