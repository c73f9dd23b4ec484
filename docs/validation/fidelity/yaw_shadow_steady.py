"""Two fins on held patterns: the yaw row alone, solved within the beat, gives the full model's turning rate.

The measurement behind docs/validation/fidelity/README.md, "The yaw row alone" (~1 min):
``PYTHONPATH=. python docs/validation/fidelity/yaw_shadow_steady.py``. The full model settles for 150 s.

For two-fin patterns (400 drawn like the benchmark's steady states with a development seed and the dev set's
periods, and the 16 of ``fidelity_report.json``), the full model is driven to its periodic steady state
(:func:`pectoral_gym.scaling.validation.yaw_balance.yaw_balance`). A *yaw shadow* then integrates the yaw row of eq.
(19)-(20) alone, ``domega/dt = tau_R(t) / J3 + tau_L(t) / J3 + munk - c4 omega |omega|``, with both fins' blade-element
moments (eqs. 16, 18, 21; the left fin mirrored, both started on their power strokes at t = 0 as in the full model)
and the Munk term as the averaged model forms it, from mean velocities (``(m1 - m2) / J3 mean(vx) mean(vy)``
at the full model's state), to its own periodic state. Printed: the mean yaw rate's relative error against
the full model, for the shadow and for the averaged model's steady state
(:func:`pectoral_gym.scaling.validation.comparison.steady_pair`),
over the pairs turning faster than 0.02 rad/s.
"""

import json
from pathlib import Path

import numba as nb
import numpy as np

from pectoral_gym.model.dynamics import fin_force_right, stroke_kinematics
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.params import FishParams
from pectoral_gym.scaling.identification.grids import draw_off_grid
from pectoral_gym.scaling.validation.comparison import steady_pair
from pectoral_gym.scaling.validation.fidelity import SEED_SETS
from pectoral_gym.scaling.validation.pattern_sets import MIN_TURN_RATE, sampling_box
from pectoral_gym.scaling.validation.yaw_balance import parse_pattern, yaw_balance

params, scaling = FishParams(), ScalingFunctions.load()
C4, J3, K_DRAG, K_INERTIA, ARM = params.c4, params.J3, params.fin_drag_constant, params.fin_inertia_constant, \
    params.fin_offset
SETTLE, WINDOW, H = 20.0, 72.0, 0.001  # the window is a multiple of every period of both sets


@nb.njit
def fin_moment(t, beat, side):
    """Yaw moment / J3 [rad/s^2] of one fin beating ``beat`` from a power stroke at t = 0 (eqs. 16, 18, 21)."""
    bias, amplitude, period, ratio = beat[0], beat[1], beat[2], beat[3]
    if amplitude <= 0.0:
        return 0.0
    power = period / (ratio + 1.0)
    s = t % period
    if s < power:
        start, end, duration = bias - amplitude, bias + amplitude, power
    else:
        start, end, duration, s = bias + amplitude, bias - amplitude, period - power, s - power
    g, gd, gdd = stroke_kinematics(s, duration, start, end)  # eq. (21)
    fx, _ = fin_force_right(g, gd, gdd, K_DRAG, K_INERTIA)  # eq. (16)
    return side * ARM * fx / J3


@nb.njit
def shadow_rate(right, left, munk):
    """Mean yaw rate [rad/s] of the in-beat yaw row over WINDOW s after SETTLE s (RK4, H s)."""
    omega, t, heading = 0.0, 0.0, 0.0
    for i in range(round((SETTLE + WINDOW) / H)):
        k = np.empty(4)
        o = omega
        for j in range(4):
            tq = t + (0.0, 0.5 * H, 0.5 * H, H)[j]
            k[j] = fin_moment(tq, right, 1.0) + fin_moment(tq, left, -1.0) + munk - C4 * o * abs(o)
            o = omega + (0.5 * H * k[j] if j < 2 else H * k[j])
        if i * H >= SETTLE - 1e-12:
            heading += H / 6.0 * (omega + 2.0 * (omega + 0.5 * H * k[0]) + 2.0 * (omega + 0.5 * H * k[1])
                                  + (omega + H * k[2]))
        omega += H / 6.0 * (k[0] + 2.0 * k[1] + 2.0 * k[2] + k[3])
        t += H
    return heading / WINDOW


def compare(name, beats):
    """Print the markdown row of ``beats (n, 2, 4)``: yaw-rate errors of the averaged model and of the shadow."""
    balance = yaw_balance(beats, scaling, params, settle=150.0, window=WINDOW)
    full = balance["omega"]
    shadow = np.array([shadow_rate(b[0], b[1], m) for b, m in zip(beats, balance["model_munk"], strict=True)])
    averaged = steady_pair(beats, scaling, params)["averaged"]["omega"]
    turning = np.abs(full) >= MIN_TURN_RATE
    print(f"| {name} ({turning.sum()} turning) | " + " | ".join(
        f"{100 * np.median(e):.2f} / {100 * np.percentile(e, 90):.1f} / {100 * e.max():.0f} %"
        for e in (np.abs(x[turning] - full[turning]) / np.abs(full[turning]) for x in (averaged, shadow))) + " |")


low, high, grid, _ = sampling_box(scaling)
rng = np.random.default_rng(SEED_SETS["dev"].seed + 55)
drawn = np.stack([draw_off_grid(rng, 400, low, high, grid, SEED_SETS["dev"].steady_periods) for _ in range(2)], axis=1)
report_rows = json.loads(Path("docs/validation/fidelity/fidelity_report.json").read_text())["steady"]["rows"]
report = np.array([parse_pattern(row["pattern"]) for row in report_rows])
print("| two-fin steady states | averaged model: yaw-rate error median / p90 / worst | yaw shadow |\n|---|---|---|")
compare("400 drawn, dev periods", drawn)
compare("fidelity_report.json's 16", report)
