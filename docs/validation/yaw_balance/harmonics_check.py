# ruff: noqa
"""How many harmonics of the single-fin yaw-rate waveform matter for the damping mean (dev patterns, seed 7)."""
import numpy as np
from pectoral_gym.model.models import FullModel
from pectoral_gym.model.params import FinBeat, FishParams
from pectoral_gym.model.steady import steady_state_batch
rng = np.random.default_rng(7)
n = 40
pat = np.column_stack([np.radians(rng.uniform(45, 135, n)), np.radians(rng.uniform(3, 30, n)),
                       np.ones(n), rng.uniform(1.1, 5, n)])
S = 256
beats = np.empty((n, 2, 4)); beats[:, 0] = pat; beats[:, 1] = FinBeat.rest().as_array()
m = FullModel(n, FishParams()); steady_state_batch(m, beats, rtol=1e-7, atol=1e-10, max_time=900, window=1.0)
om = np.empty((n, S))
for k in range(S):
    m.advance(1.0 / S); om[:, k] = m.state[:, 5]
w = om.mean(1, keepdims=True); wig = om - w
true = np.mean(om * np.abs(om), 1)
th = 2*np.pi*np.arange(1, S+1)/S
c = (2.0/S) * wig @ np.exp(-1j*np.outer(th, np.arange(1, 40)))
def damp(H, N):
    s = 2*np.pi*np.arange(N)/N
    o = np.real(c[:, :H] @ np.exp(1j*np.outer(np.arange(1, H+1), s)))
    x = w + o
    return np.mean(x*np.abs(x), 1)
A = np.pi/2*np.abs(wig).mean(1)
print("mean damping scale", np.median(np.abs(true)), "osc A median", np.median(A))
for H in (1, 2, 3, 4, 6, 8, 12):
    for N in (8, 16, 32, 256):
        if N < 2*H+1: continue
        e = np.abs(damp(H, N)-true)
        print(f"H={H:2d} N={N:3d} max|err| {e.max():.2e} median {np.median(e):.2e}  rel-to-w^2 {np.max(e/np.abs(true)):.3f}")
