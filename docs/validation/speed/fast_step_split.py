"""The averaged model's CPU per fish and control period with its ``corrections`` bits set one by one.

``python docs/validation/speed/fast_step_split.py``: 512 fish of ``spec.AVERAGED`` (the shipped K), both fins
given a new pattern every 0.5 s for 60 s (the seeded patterns of ``fast_step_accuracy.py``), the model's own
serial kernel (``stepping._ADVANCE[True].serial``) called with each combination of the bits
(``TRANSITIONS``, ``RIPPLE_OFFSETS``, ``FAST_STEP``); the best of five identical runs, compile excluded.
"""

import math
import time

import numpy as np

from pectoral_gym.model import stepping
from pectoral_gym.model.spec import AVERAGED
from pectoral_gym.model.stroke_corrections import FAST_STEP, RIPPLE_OFFSETS, TRANSITIONS

n, steps = 512, 120
rng = np.random.default_rng(12)
low = np.array([math.radians(45.0), 0.0, 0.5, 1.0])
high = np.array([math.radians(135.0), math.radians(30.0), 2.0, 5.0])
patterns = low + (high - low) * rng.random((steps, n, 2, 4))
kernel = stepping._ADVANCE[True].serial
model = AVERAGED.build(n)


def cpu_per_step(corrections: int) -> float:
    """Best CPU time [us] per fish and 0.5 s over five runs with ``corrections``."""
    best = math.inf
    for _ in range(5):
        model.reset()
        elapsed = 0.0
        for k in range(steps):
            model.command_array(patterns[k])
            t0 = time.process_time()
            kernel(model.state, model.fins, model.forcing_cache, model.pending, model.integral, model.coef, 0.5,
                   model.dt_max, 1.0, True, int(model.mode), corrections, tuple(model._packed_tables))
            elapsed += time.process_time() - t0
        best = min(best, elapsed)
    return best / (n * steps) * 1e6


cpu_per_step(0)  # compile
both = TRANSITIONS | RIPPLE_OFFSETS
for name, bits in (("default, both corrections (v2)", both), ("default, none (v0)", 0),
                   ("fast, both corrections", FAST_STEP | both), ("fast, transitions", FAST_STEP | TRANSITIONS),
                   ("fast, ripple offsets", FAST_STEP | RIPPLE_OFFSETS), ("fast, none", FAST_STEP)):
    print(f"| {name} | {cpu_per_step(bits):.3f} us |")
