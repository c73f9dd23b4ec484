# ruff: noqa
"""model.advance at 4096 fish, patterns changed every call (random, env action ranges), seconds per env-step."""
import sys, time, numpy as np
from pectoral_gym.model.models import AveragedModel
from pectoral_gym.model.kfunctions import ScalingFunctions
n = 4096
rng = np.random.default_rng(0)
def beats():
    b = np.empty((n, 2, 4))
    b[..., 0] = np.radians(rng.uniform(45, 135, (n, 2))); b[..., 1] = np.radians(rng.uniform(0, 30, (n, 2)))
    b[..., 2] = rng.uniform(0.5, 2.0, (n, 2)); b[..., 3] = rng.uniform(1.0, 5.0, (n, 2))
    return b
models = {}
for name in sys.argv[1:]:
    s = "identified" if name == "shipped" else ScalingFunctions.load(name)
    models[name] = AveragedModel(n, scaling=s)
pre = [beats() for _ in range(50)]
for m in models.values():
    m.reset(right=pre[0][:, 0], left=pre[0][:, 1])
    for b in pre[:5]:
        m.command_array(b); m.advance(0.1)
res = {k: [] for k in models}
for rep in range(5):
    for name, m in models.items():
        t = time.perf_counter()
        for b in pre:
            m.command_array(b); m.advance(0.1)
        res[name].append((time.perf_counter() - t) / (50 * n))
for name, v in res.items():
    print(f"{name}: best {min(v)*1e6:.3f} us/env-step, median {np.median(v)*1e6:.3f}")
