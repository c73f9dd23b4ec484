"""RK4 substeps, segments and latches of the averaged model per 0.5 s, patterns changing every 0.5 s.

Needs a checkout with ``count_steps.patch`` applied (it counts into three extra forcing-cache
fields); see README.md here. 512 fish, seeded patterns from the envs' action ranges, transitions on
(the PPO file's setting), ripple offsets off (the envs' default); 20 periods of warm-up, 99 counted.
"""

import numpy as np

from pectoral_gym.model import forcing_cache as fc
from pectoral_gym.model.models import AveragedModel
from pectoral_gym.scaling.validation.fidelity import draw_patterns

N, PERIODS, WARM_UP = 512, 120, 20
model = AveragedModel(N, transitions=True, ripple_offsets=False)
model.reset()
patterns = draw_patterns(np.random.default_rng(1), N, PERIODS)
for k in range(PERIODS):
    model.command_array(np.ascontiguousarray(patterns[:, k]))
    if k == WARM_UP:
        model.forcing_cache[:, 0, fc.N_RK4:] = 0.0
    model.advance(0.5)
counts = model.forcing_cache[:, 0, fc.N_RK4:].sum(axis=0) / (N * (PERIODS - WARM_UP - 1))
rk4, segments, latches = counts
print(f"per fish and 0.5 s: RK4 steps {rk4:.2f}, segments {segments:.2f}, latches {latches:.2f}")
