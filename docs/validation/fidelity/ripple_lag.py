"""One fin started on its pattern: how far the averaged model's heading and speed lag the full model's beat means.

The measurements behind docs/model.md section 3.8, with the ripple offset off and on:
``PYTHONPATH=. python docs/validation/fidelity/ripple_lag.py`` (~1 min; 128 one-fin patterns of the dev seed).
Beat means of the full model over one fin period, centred; the averaged model at the window's centre.
"""

import numpy as np

from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.models import AveragedModel, FullModel
from pectoral_gym.model.params import FishParams
from pectoral_gym.scaling.validation.fidelity import SEED_SETS, draw_patterns

N, DT, DURATION = 128, 0.02, 40.0
rng = np.random.default_rng(SEED_SETS["dev"].seed)
beats = draw_patterns(rng, N, 1)[:, 0]
beats[:, 1] = (np.pi / 2, 0.0, 1.0, 1.0)  # left fin at rest
params, scaling = FishParams(), ScalingFunctions.load()


def run(model):
    """States ``(N, steps + 1, 6)`` every DT s of ``model`` started on the patterns."""
    model.reset(right=beats[:, 0], left=beats[:, 1])
    out = [model.state.copy()]
    for _ in range(round(DURATION / DT)):
        model.advance(DT)
        out.append(model.state.copy())
    return np.stack(out, 1)


def beat_mean(x, period):
    """Means of ``x`` over windows of one period, and the offset of a window's centre (samples)."""
    w = max(1, round(period / DT))
    c = np.cumsum(np.r_[0.0, x])
    return (c[w:] - c[:-w]) / w, w // 2  # mean over [k, k + w), its centre offset


full = run(FullModel(N, params))
speed_full = np.hypot(full[:, :, 3], full[:, :, 4])
for offsets in (False, True):
    avg = run(AveragedModel(N, params, scaling=scaling, ripple_offsets=offsets))
    speed_avg = np.hypot(avg[:, :, 3], avg[:, :, 4])
    lag = {2: [], 35: []}
    slow = {2: [], 5: [], 10: []}
    for i in range(N):
        psi, c = beat_mean(full[i, :, 2], beats[i, 0, 2])
        sp, _ = beat_mean(speed_full[i], beats[i, 0, 2])
        for t in lag:
            k = round(t / DT) - c
            lag[t].append(np.degrees(psi[k] - avg[i, k + c, 2]))
        for t in slow:
            k = round(t / DT) - c
            window = slice(k, k + 2 * c)
            slow[t].append(speed_avg[i, window].mean() / speed_full[i, window].mean() - 1.0)
    lag = {t: np.abs(v) for t, v in lag.items()}
    change = np.abs(np.array(lag[35]) - np.array(lag[2]))
    print(f"ripple offsets {'on ' if offsets else 'off'}: |heading lag| median / p90 at 2 s "
          f"{np.median(lag[2]):.2f} / {np.percentile(lag[2], 90):.2f} deg, at 35 s {np.median(lag[35]):.2f} / "
          f"{np.percentile(lag[35], 90):.2f} deg (change {np.median(change):.2f} deg); averaged speed / full - 1, "
          "median: " + ", ".join(f"{100 * np.median(v):+.1f} % at {t} s" for t, v in slow.items()))
