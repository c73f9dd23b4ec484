"""How much more (or less) the averaged model turns than the full model, under changing commands.

The measurements behind docs/model.md section 3.9: ``PYTHONPATH=. python docs/validation/fidelity/yaw_slope.py``
(~1 min). 128 fish, 40 s, patterns drawn from the envs' action ranges with the dev seed + 99 (a
development set: neither the benchmark's dev nor its report patterns), one fin (the left at rest) or
two, changed every 0.5 s or 4 s, or held. Prints the position and heading errors as the fidelity
benchmark defines them and the least-squares slope of the averaged model's total turns on the full
model's (1: the same turning on average; above 1: the averaged fish turns more).
"""

import numpy as np

from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.params import FinBeat, FishParams
from pectoral_gym.scaling.validation.fidelity import SEED_SETS, draw_patterns, open_loop, open_loop_errors

N, DURATION = 128, 40.0
params, scaling = FishParams(), ScalingFunctions.load()
two_fins = draw_patterns(np.random.default_rng(SEED_SETS["dev"].seed + 99), N, 80)
one_fin = two_fins.copy()
one_fin[:, :, 1] = FinBeat.rest().as_array()
cases = {"one fin, every 0.5 s": (one_fin, 0.5), "one fin, every 4 s": (one_fin, 4.0),
         "two fins, every 0.5 s": (two_fins, 0.5), "two fins, every 4 s": (two_fins, 4.0),
         "two fins, held": (two_fins, None)}
print("| scenario | position median / p90 | heading median / p90 [deg] | turn slope |\n|---|---|---|---|")
for name, (schedule, every) in cases.items():
    full, averaged = (open_loop(kind, schedule, every, DURATION, params, scaling) for kind in ("full", "averaged"))
    err = open_loop_errors(full, averaged)
    turn_full, turn_averaged = full[:, -1, 2] - full[:, 0, 2], averaged[:, -1, 2] - averaged[:, 0, 2]
    slope = np.sum(turn_averaged * turn_full) / np.sum(turn_full**2)
    position, heading = 100 * err["position"], err["heading_deg"]
    print(f"| {name} | {np.median(position):.1f} / {np.percentile(position, 90):.1f} % | "
          f"{np.median(heading):.1f} / {np.percentile(heading, 90):.1f} | {slope:.3f} |")
