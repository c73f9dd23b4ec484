"""``model.advance`` rates side by side: averaged, averaged with the in-beat yaw row, full fast, full reference.

The measurement behind docs/validation/fidelity/README.md, "Resolving the yaw row" (~1 min): 4096 fish,
seeded patterns from the envs' action ranges, new every 0.5 s, best of 5 round-robin passes of 20 s. The
in-beat yaw row needs ``inbeat_yaw.patch`` applied in a worktree (without it that row is the averaged model)::

    git worktree add ../inbeat HEAD && (cd ../inbeat && git apply ../main/docs/validation/fidelity/inbeat_yaw.patch)
    NUMBA_CACHE_DIR=$(mktemp -d) PYTHONPATH=../inbeat python docs/validation/fidelity/inbeat_yaw_speed.py
"""

import os
import time

import numpy as np

from pectoral_gym.model.models import AveragedModel, FullModel
from pectoral_gym.scaling.validation.fidelity import draw_patterns

N, STEPS = 4096, 40
pat = draw_patterns(np.random.default_rng(1), N, STEPS).transpose(1, 0, 2, 3).copy()
kinds = {"averaged": (lambda: AveragedModel(N), "0"),
         "averaged + in-beat yaw (patch)": (lambda: AveragedModel(N), "1"),
         "full, fast": (lambda: FullModel(N, integration="fast"), "0"),
         "full, reference": (lambda: FullModel(N), "0")}
models = {k: (f(), flag) for k, (f, flag) in kinds.items()}
res = {k: [] for k in kinds}
for rep in range(6):
    for k, (m, flag) in models.items():
        os.environ["INBEAT_YAW"] = flag
        m.reset()
        t = time.perf_counter()
        for c in pat:
            m.command_array(c)
            m.advance(0.5)
        if rep:
            res[k].append(time.perf_counter() - t)
for k in kinds:
    print(f"{k:32} {N*STEPS/min(res[k])/1e3:6.0f} k fish-steps/s")
