"""Error of the averaged model's steps against a tight-tolerance reference, over seeded random patterns.

``python docs/validation/speed/fast_step_accuracy.py [NUM_FISH] [SECONDS]`` (defaults 256 and 60): the
averaged model as ``PectoralFish-Averaged-v2`` runs it (both corrections, the shipped K), every fish from
rest, both fins given a new pattern every 0.5 s (the control period), drawn uniformly (seeded) from the
envs' action ranges (bias 45-135 deg, amplitude 0-30 deg, period 0.5-2 s, ratio 1-5). Each variant is
a build of ``stepping._advance_model`` with its step constants bound (``jit.kernel_variant``):

* ``reference``: the default step with ``h * rate <= 0.1`` and ``dt_max`` 0.005 s;
* ``default``: the model as shipped (``ACCURATE_STEP`` 1.5, ``dt_max`` 0.25 s);
* ``fast a``: the ``fast_step`` option (``fast_step.py``) with ``h * rate <= a``.

Prints, per variant, the position error [mm] (end and the worst over the run, median and worst fish),
heading [deg] and speed [mm/s] errors at the control instants, and the model's CPU time per fish and
control period (serial loop, the best of five identical runs; compile excluded).
"""

import math
import sys
import time

import numpy as np

from pectoral_gym.model import stepping
from pectoral_gym.model.jit import kernel_pair, kernel_variant
from pectoral_gym.model.spec import AVERAGED
from pectoral_gym.model.stroke_corrections import FAST_STEP

n = int(sys.argv[1]) if len(sys.argv) > 1 else 256
seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 60.0
PERIOD = 0.5
TIMING_PASSES = 5
ARGS = "state, fins, cache, pending, integral, coef, duration, dt_max, min_substeps, averaged, mode, corrections, " \
       "packed_tables"
rng = np.random.default_rng(12)
steps = int(round(seconds / PERIOD))
low = np.array([math.radians(45.0), 0.0, 0.5, 1.0])
high = np.array([math.radians(135.0), math.radians(30.0), 2.0, 5.0])
patterns = low + (high - low) * rng.random((steps, n, 2, 4))

variants = {  # name: (bindings, dt_max, fast)
    "reference": ({"ACCURATE_STEP": 0.1}, 0.005, False),
    "default": ({}, None, False),
    **{f"fast {a}": ({"FAST_ACCURATE_STEP": a}, None, True) for a in (1.5, 2.0, 2.25, 2.5)},
}


def run(name, bindings, dt_max, fast):
    """The poses ``(steps, n, 6)`` at the control instants of variant ``name``, and its best CPU time [s]."""
    kernel = kernel_variant(stepping._advance_model, "accuracy_" + name.replace(" ", "_").replace(".", "_"),
                            {"AVERAGED": True, **bindings})
    loops = kernel_pair(kernel, ARGS)
    model = AVERAGED.build(n)
    model.reset()
    dt = model.dt_max if dt_max is None else dt_max
    corrections = model.corrections | (FAST_STEP if fast else 0)
    path = np.empty((steps, n, 6))

    def advance():
        loops.serial(model.state, model.fins, model.forcing_cache, model.pending, model.integral, model.coef,
                     PERIOD, dt, float(model.min_substeps), True, int(model.mode), int(corrections),
                     tuple(model._packed_tables))

    advance()  # compile (from rest, no pattern: nothing moves)
    best = math.inf
    for _ in range(TIMING_PASSES):  # the same run each time; the last one's path is kept
        model.reset()
        elapsed = 0.0
        for k in range(steps):
            model.command_array(patterns[k])
            t0 = time.process_time()
            advance()
            elapsed += time.process_time() - t0
            path[k] = model.state
        best = min(best, elapsed)
    return path, best


paths = {}
for name, (bindings, dt_max, fast) in variants.items():
    paths[name], elapsed = run(name, bindings, dt_max, fast)
    print(f"{name}: {elapsed / (steps * n) * 1e6:.3f} us of CPU per fish and 0.5 s (serial loop, best of "
          f"{TIMING_PASSES})", flush=True)
ref = paths.pop("reference")
print(f"\n{n} fish, {seconds:g} s, patterns every {PERIOD} s; errors against the reference "
      "(median fish / worst fish)")
print("| variant | position at end [mm] | position, worst instant [mm] | heading, worst [deg] | speed, worst [mm/s] |")
print("|---|---|---|---|---|")
for name, path in paths.items():
    pos = np.hypot(path[..., 0] - ref[..., 0], path[..., 1] - ref[..., 1]) * 1e3
    head = np.degrees(np.abs(path[..., 2] - ref[..., 2]))
    vel = np.hypot(path[..., 3] - ref[..., 3], path[..., 4] - ref[..., 4]) * 1e3
    end, worst_pos, worst_head, worst_vel = pos[-1], pos.max(axis=0), head.max(axis=0), vel.max(axis=0)
    print(f"| {name} | {np.median(end):.3f} / {end.max():.3f} | {np.median(worst_pos):.3f} / {worst_pos.max():.3f} "
          f"| {np.median(worst_head):.4f} / {worst_head.max():.4f} "
          f"| {np.median(worst_vel):.3f} / {worst_vel.max():.3f} |")
