"""The fidelity scenarios in a world without the quadratic yaw damping: what the averaged model's structure can reach.

Run with ``linear_damping.patch`` applied in a worktree (docs/validation/fidelity/README.md, "Where the error
with changing commands comes from")::

    git worktree add ../lin HEAD && (cd ../lin && git apply ../main/docs/validation/fidelity/linear_damping.patch)
    LINEAR_YAW_DAMPING=0.4 NUMBA_CACHE_DIR=$(mktemp -d) PYTHONPATH=../lin \
        python docs/validation/fidelity/linear_world.py

(~1 min). Both models then have the linear yaw damping ``c4 0.4 rad/s omega``, equal surge and sway
masses (no Munk moment) and K = 1, and run the benchmark's open-loop scenarios on the report set's
schedules (``python -m pectoral_gym.scaling fidelity --set report``), split by fins as the benchmark does. Without
``LINEAR_YAW_DAMPING`` (or without the patch) the same script gives the benchmark's own world with K = 1
and no Munk moment.
"""

import math

import numpy as np

from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.params import FishParams
from pectoral_gym.scaling.validation.fidelity import (
    DURATION,
    FIN_SPLITS,
    SCENARIOS,
    SEED_SETS,
    draw_patterns,
    open_loop,
    open_loop_errors,
    split_fins,
)

params = FishParams()
params = params.replace(added_mass_y=params.added_mass_x)
scaling = ScalingFunctions.unit()
rng = np.random.default_rng(SEED_SETS["report"].seed)  # the benchmark's draws, in its order
schedules = {name: draw_patterns(rng, 128, 1 if every is None else math.ceil(DURATION / every))
             for name, every in SCENARIOS.items()}
print("| scenario | two fins | one fin | mirrored fins |\n|---|---|---|---|")
for name, every in SCENARIOS.items():
    cells = []
    for split in (None, *FIN_SPLITS):
        schedule = schedules[name] if split is None else split_fins(schedules[name], split)
        full, averaged = (open_loop(kind, schedule, every, DURATION, params, scaling) for kind in ("full", "averaged"))
        err = 100 * open_loop_errors(full, averaged)["position"]
        cells.append(f"{np.median(err):.1f} / {np.percentile(err, 90):.1f} %")
    print(f"| {name} | " + " | ".join(cells) + " |")
