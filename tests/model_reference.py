"""The independent reference of the model tests: eqs. (19)-(21) typed in here, solved by ``scipy.integrate``.

* eq. (19)-(20) solved with ``scipy.integrate.solve_ivp`` (DOP853, tight tolerances, restarted at every stroke
  boundary), with the fin forcing from eq. (21) and the closed-form blade-element force
  (:func:`reference_full`);
* the cycle-averaged forcing in closed form with Bessel's J1 (:func:`closed_form_average`,
  :func:`reference_averaged`);
* the coefficients of Table 1 written out (:data:`M1`, :data:`C1`, ...), not read from the package.

Nothing here calls the package's integrators; :func:`run` and :func:`cycle_average` drive a package model.
"""

import math

import numpy as np
from scipy.integrate import solve_ivp
from scipy.special import j1

from pectoral_gym import FinBeat, FishParams

P = FishParams()
M1, M2, J3 = 0.795 + 0.095, 0.795 + 0.1794, 4.26e-4 + 2.7e-5
C1 = 0.5 * 1000 * 0.0325 * 0.3870
C2 = 0.5 * 1000 * 0.0325 * 0.0808
CM = 8.5e-3
CP = 0.03
K_DRAG = 4.1464 * 1000 * 0.041 * 0.061**3 / 6
K_INERTIA = 0.008 * 0.061 / 2

TURN = FinBeat.from_degrees(90, 20, 1.0, 4.0)
FORWARD = FinBeat.from_degrees(100, 12, 0.8, 5.0)


# --------------------------------------------------------------------------- independent reference


def eq21(t, beat):
    g0, ga, tp, zeta = beat
    t = t % tp
    t1 = tp / (zeta + 1.0)
    if t <= t1:
        w = math.pi / t1
        return g0 - ga * math.cos(w * t), ga * w * math.sin(w * t), ga * w * w * math.cos(w * t)
    w = math.pi / (tp - t1)
    s = t - t1
    return g0 + ga * math.cos(w * s), -ga * w * math.sin(w * s), -ga * w * w * math.cos(w * s)


def right_fin_force(g, gd, gdd):
    m = np.array([math.cos(g), -math.sin(g)])
    n = np.array([-math.sin(g), -math.cos(g)])
    return -K_DRAG * gd * abs(gd) * n - K_INERTIA * (gdd * n - gd * gd * m)


def forcing(t, right, left):
    fr = right_fin_force(*eq21(t, right)) if right is not None else np.zeros(2)
    fl = right_fin_force(*eq21(t, left)) if left is not None else np.zeros(2)
    fl = fl * np.array([1.0, -1.0])  # mirror image
    return fr[0] + fl[0], fr[1] + fl[1], CP * fr[0] - CP * fl[0]


def eq19(state, f):
    _, _, psi, vx, vy, om = state
    fx, fy, tau = f
    speed = math.hypot(vx, vy)
    alpha = math.atan(vy / vx) if vx != 0 else 0.0
    return [
        vx * math.cos(psi) - vy * math.sin(psi),
        vx * math.sin(psi) + vy * math.cos(psi),
        om,
        M2 / M1 * vy * om - C1 / M1 * vx * speed + C2 / M1 * vy * speed * alpha + fx / M1,
        -M1 / M2 * vx * om - C1 / M2 * vy * speed - C2 / M2 * vx * speed * alpha + fy / M2,
        (M1 - M2) / J3 * vx * vy - CM / J3 * om * abs(om) + tau / J3,
    ]


def boundaries(beat, t_end):
    if beat is None:
        return []
    g0, ga, tp, zeta = beat
    t1 = tp / (zeta + 1.0)
    out, k = [], 0
    while k * tp < t_end:
        out += [k * tp + t1, (k + 1) * tp]
        k += 1
    return out


def reference_full(right, left, t_end, y0=None):
    """solve_ivp of eq. (19) with eq. (21) forcing, restarted at every stroke boundary."""
    r = None if right is None else tuple(right.as_array())
    lf = None if left is None else tuple(left.as_array())
    cuts = sorted({0.0, t_end, *[b for b in boundaries(r, t_end) + boundaries(lf, t_end) if b < t_end]})
    y = np.zeros(6) if y0 is None else np.asarray(y0, float)
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        sol = solve_ivp(lambda t, s: eq19(s, forcing(t, r, lf)), (a, b), y, method="DOP853", rtol=1e-11, atol=1e-13)
        y = sol.y[:, -1]
    return y


def closed_form_average(beat, side):
    g0, ga, tp, zeta = beat.as_array()
    base = K_DRAG * math.pi**2 * (zeta**2 - 1) / (zeta * tp**2) * ga * j1(ga)
    fx, fy = base * math.sin(g0), base * math.cos(g0)
    return np.array([fx, side * fy, side * CP * fx])


def reference_averaged(right, left, t_end, y0=None):
    f = closed_form_average(right, 1.0) + closed_form_average(left, -1.0)
    sol = solve_ivp(lambda t, s: eq19(s, f), (0, t_end), np.zeros(6) if y0 is None else y0, method="DOP853",
                    rtol=1e-11, atol=1e-13)
    return sol.y[:, -1]


def run(model, duration, **reset):
    model.reset(**reset)
    model.advance(duration)
    return model.state.copy()


def cycle_average(model, window):
    before = model.integral.copy()
    model.advance(window)
    return (model.integral - before) / window
