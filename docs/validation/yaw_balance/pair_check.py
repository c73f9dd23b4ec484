# ruff: noqa
import sys, numpy as np
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.models import FullModel
from pectoral_gym.model.params import FinBeat, FishParams, body_coefficients
from pectoral_gym.model.averaging import waveform_samples
from pectoral_gym.model.dynamics import waveform_square_mean
from pectoral_gym.scaling.validation.yaw_balance import parse_pattern, yaw_balance
from pectoral_gym.scaling.identification.reference import yaw_waveform_harmonics
lab = sys.argv[1]
S = ScalingFunctions.load(sys.argv[2])
b = parse_pattern(lab)
P = FishParams(); c4 = body_coefficients(P).c4
rest = FinBeat.rest().as_array()
T = b[0, 2]
assert b[0, 2] == b[1, 2]
beats = np.array([b, [b[0], rest], [rest, b[1]]])
m = FullModel(3, P); m.reset(right=beats[:, 0], left=beats[:, 1]); m.advance(240 * T / T)
# sample one period from a power-stroke start: time now 240 s; is it a multiple of T?
n_per = round(240 / T); m2 = FullModel(3, P); m2.reset(right=beats[:, 0], left=beats[:, 1]); m2.advance(n_per * T)
om = []
for k in range(64):
    m2.advance(T / 64); om.append(m2.state[:, 5].copy())
om = np.array(om).T
c = yaw_waveform_harmonics(om, 8)
print("mean omega two/R/L", om.mean(1))
print("measured two-fin c1..3", np.round(c[0, :3], 4))
print("measured R alone", np.round(c[1, :3], 4), " spline R", np.round(S.yaw_waveform(*b[0])[:3], 4))
print("measured L alone", np.round(c[2, :3], 4), " spline L (mirrored)", np.round(-S.yaw_waveform(*b[1])[:3], 4))
print("superposed", np.round(c[1, :3] + c[2, :3], 4))
w = om[0].mean()
print("damping full", c4 * np.mean(om[0] * np.abs(om[0])),
      "superposed-measured", c4 * waveform_square_mean(w, waveform_samples(c[1] + c[2])),
      "model", c4 * waveform_square_mean(w, waveform_samples(S.yaw_waveform(*b[0]) - S.yaw_waveform(*b[1]))),
      "two-fin own harmonics", c4 * waveform_square_mean(w, waveform_samples(c[0])))
lam = 2 * c4 * np.abs(om).mean(1)  # two, R, L
Om = 2 * np.pi / T
k = np.arange(1, 9)
def resp(l): return 1j * k * Om + l
pred = (c[1] * resp(lam[1]) + c[2] * resp(lam[2])) / resp(lam[0])
print("lambda two/R/L", lam)
print("predicted with measured lambda", np.round(pred[:3], 4))
print("damping with it", c4 * waveform_square_mean(w, waveform_samples(pred)))
# self-consistent lambda from the prediction itself
l = lam[0]
for it in range(5):
    o = (c[1] * resp(lam[1]) + c[2] * resp(lam[2])) / resp(l)
    l = 2 * c4 * np.mean(np.abs(w + waveform_samples(o)))
    print(" iter", it, "lambda", l, "damping", c4 * waveform_square_mean(w, waveform_samples(o)))
