# ruff: noqa
"""One-off check (docs/model.md 3.6): damping of two-fin steady states, full model vs averaging choices for fins with different periods.

PYTHONPATH=. python docs/validation/yaw_balance/ratio_check.py pectoral_gym/data/scaling_coefficients_waveform.json "R(101, 23.8, 1.8, 4.299) L(92.87, 20.81, 0.9, 2.261)"
"""
import sys, numpy as np
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.params import FishParams, body_coefficients
from pectoral_gym.model.averaging import waveform_samples, combined_waveform
from pectoral_gym.model.dynamics import waveform_square_mean
from pectoral_gym.scaling.validation.yaw_balance import parse_pattern, yaw_balance
S = ScalingFunctions.load(sys.argv[1])
P = FishParams(); c4 = body_coefficients(P).c4
for lab in sys.argv[2:]:
    b = parse_pattern(lab)
    res = yaw_balance(b[None], S, P, settle=240.0, window=36.0)
    w = res["omega"][0]
    cR, cL = S.yaw_waveform(*b[0]), -S.yaw_waveform(*b[1])
    mR, mL = S.yaw_mean_abs(*b[0]), S.yaw_mean_abs(*b[1])
    TR, TL = b[0, 2], b[1, 2]
    k = np.arange(1, 9)
    # diagonal (frozen relative phase), averaged over relative phases
    diag = np.mean([waveform_square_mean(w, combined_waveform(np.array([cR, cL * np.exp(1j * k * s)]), np.array([mR, mL]), np.array([TR, TL]), w, c4)) for s in np.linspace(0, 2*np.pi, 64, endpoint=False)])
    # time window over the common period (both fins start their power stroke at t = 0)
    Tc = max(TR, TL) * 6
    t = np.linspace(0, Tc, 4096, endpoint=False)
    def sig(c, T): return np.real(np.exp(1j * np.outer(t * 2 * np.pi / T, k)) @ c)
    o = sig(cR, TR) + sig(cL, TL)
    x = w + o
    tw = np.mean(x * np.abs(x))
    # torus (independent phases)
    th = np.linspace(0, 2*np.pi, 128, endpoint=False)
    oR = np.real(np.exp(1j*np.outer(th, k)) @ cR); oL = np.real(np.exp(1j*np.outer(th, k)) @ cL)
    X = w + oR[:, None] + oL[None, :]
    tor = np.mean(X*np.abs(X))
    print(f"{lab}: full {res['full_damping'][0]:.4f}  model(yaw_balance) {res['model_damping'][0]:.4f} diag-avg {c4*diag:.4f}  time-window(no rate corr) {c4*tw:.4f} torus {c4*tor:.4f}  residual {res['residual'][0]:+.4f}")
