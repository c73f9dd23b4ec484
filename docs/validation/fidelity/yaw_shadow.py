r"""Does the kick of a pattern change live in the yaw equation alone? A scalar in-beat yaw simulation says yes.

The measurement behind docs/validation/fidelity/README.md, "A yaw shadow of each change" (~1 min), run with
``change_kick_scales.patch`` applied in a worktree and the averaged model's transitional yaw terms off::

    git worktree add ../kick HEAD && (cd ../kick && git apply ../main/docs/validation/fidelity/change_kick_scales.patch)
    KICK_SWEPT=0 KICK_EXCESS=0 KICK_OFFSET=0 KICK_GAIN_EXPONENT=0 NUMBA_CACHE_DIR=$(mktemp -d) \
        PYTHONPATH=../kick python docs/validation/fidelity/yaw_shadow.py

The fish of ``change_kick.py`` (same seed and switch times). For each, a *yaw shadow* integrates the yaw row
of eq. (19)-(20) alone, ``domega/dt = tau(t) / J3 + munk(t) - c4 omega |omega|``, with the blade-element
moment of the fin's actual strokes (eqs. 16, 18; the pattern ``A`` from t = 0, the switch, the transitional
half-stroke, then ``B``), the Munk term from the *averaged* model's own velocities, and next to it the
averaged model's yaw closure without transitional terms (K-scaled cycle means, the phasor damping of
docs/model.md 3.6, the latched pattern). Their heading difference, measured with change_kick.py's windows,
is the shadow's estimate of the kick that the averaged model without transitional yaw terms misses. Printed:
that model's kick error, and what is left of it once the shadow's estimate is added.
"""

import math

import change_kick as ck  # this folder (the script's own): change_kick.py's fish, recording and windows
import numba as nb
import numpy as np

from pectoral_gym.model.averaging import EXACT, averaged_fin_forcing
from pectoral_gym.model.dynamics import fin_force_right, oscillating_square_mean, stroke_kinematics
from pectoral_gym.model.models import AveragedModel, FullModel
from pectoral_gym.model.params import coefficient_vector

H = 0.002  # s, the shadows' step
params, scaling, pairs, switch = ck.params, ck.scaling, ck.pairs, ck.switch
C4, J3, MUNK = params.c4, params.J3, (params.m1 - params.m2) / params.J3
K_DRAG, K_INERTIA, ARM = params.fin_drag_constant, params.fin_inertia_constant, params.fin_offset


@nb.njit
def _moment(t, starts, durations, angle_from, angle_to):
    j = np.searchsorted(starts, t, side="right") - 1
    g, gd, gdd = stroke_kinematics(t - starts[j], durations[j], angle_from[j], angle_to[j])  # eq. (21)
    fx, _ = fin_force_right(g, gd, gdd, K_DRAG, K_INERTIA)  # eq. (16)
    return ARM * fx / J3  # eq. (18), right fin


@nb.njit
def shadow_heading(t0, t1, omega0, starts, durations, angle_from, angle_to, munk_t, munk):
    """Heading every H s of the in-beat yaw row: exact moment, Munk term interpolated, quadratic damping."""
    n = round((t1 - t0) / H)
    psi, omega, t = np.zeros(n + 1), omega0, t0
    for i in range(n):
        m = np.interp(t, munk_t, munk)
        k1 = _moment(t, starts, durations, angle_from, angle_to) + m - C4 * omega * abs(omega)
        o2 = omega + 0.5 * H * k1
        k2 = _moment(t + 0.5 * H, starts, durations, angle_from, angle_to) + m - C4 * o2 * abs(o2)
        o3 = omega + 0.5 * H * k2
        k3 = _moment(t + 0.5 * H, starts, durations, angle_from, angle_to) + m - C4 * o3 * abs(o3)
        o4 = omega + H * k3
        k4 = _moment(t + H, starts, durations, angle_from, angle_to) + m - C4 * o4 * abs(o4)
        psi[i + 1] = psi[i] + H / 6.0 * (omega + 2.0 * o2 + 2.0 * o3 + o4)
        omega += H / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        t += H
    return psi


def strokes(a, b, switch_time, t_end):
    """Half-strokes (start, duration, from, to) of pattern ``a`` from t = 0, ``b`` latched at the next turning point."""
    rows, t, power, pattern, angle = [], 0.0, True, a, a[0] - a[1]
    while t < t_end:
        if pattern is a and t >= switch_time - 1e-12:
            pattern = b
        bias, amplitude, period, ratio = pattern
        duration = period / (ratio + 1.0) if power else period * ratio / (ratio + 1.0)
        to = bias + amplitude if power else bias - amplitude
        rows.append((t, duration, angle, to))
        t, angle, power = t + duration, to, not power
    return [np.array(c) for c in zip(*rows, strict=True)]


def closure_heading(t0, t1, omega0, latch, a, b, munk_t, munk):
    """Heading every H s of the averaged model's yaw row without transitional terms (docs/model.md 3.6)."""
    coef, tables = coefficient_vector(params), scaling.kernel_arrays()
    moment = [averaged_fin_forcing(*p, 1.0, coef, EXACT, tables)[2] / J3 for p in (a, b)]
    amplitude = [scaling.yaw_oscillation(*p)[0] for p in (a, b)]
    n = round((t1 - t0) / H)
    psi, omega, t = np.zeros(n + 1), omega0, t0
    for i in range(n):
        p, m = int(t >= latch - 1e-12), np.interp(t, munk_t, munk)

        def f(w, p=p, m=m):
            return moment[p] + m - C4 * oscillating_square_mean(w, amplitude[p])

        k1 = f(omega)
        k2 = f(omega + 0.5 * H * k1)
        k3 = f(omega + 0.5 * H * k2)
        k4 = f(omega + H * k3)
        psi[i + 1] = psi[i] + H / 6.0 * ((omega) + 2.0 * (omega + 0.5 * H * k1) + 2.0 * (omega + 0.5 * H * k2)
                                         + (omega + H * k3))
        omega += H / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        t += H
    return psi


full, at = ck.record(FullModel(ck.N, params), pairs)
averaged, _ = ck.record(AveragedModel(ck.N, params, scaling=scaling), pairs)
grid = ck.START + ck.DT * np.arange(full.shape[1])
error = ck.kick(averaged[:, :, 2] - full[:, :, 2], grid, pairs)
estimate = np.empty(ck.N)
for i in range(ck.N):
    a, b = pairs[i, 0, 0], pairs[i, 1, 0]
    t0, t1 = switch[i] - 4.0 * a[2], switch[i] + ck.AFTER + b[2] + 0.1
    starts, durations, angle_from, angle_to = strokes(a, b, at[i], t1 + b[2])
    latch = starts[np.searchsorted(starts, at[i] - 1e-12)]
    munk = MUNK * averaged[i, :, 3] * averaged[i, :, 4]
    omega0 = float(np.interp(t0, grid, averaged[i, :, 5]))
    gap = (shadow_heading(t0, t1, omega0, starts, durations, angle_from, angle_to, grid, munk)
           - closure_heading(t0, t1, omega0, latch, a, b, grid, munk))
    estimate[i] = ck.kick(gap[None, :], t0 + H * np.arange(gap.size), pairs, [i])[0]
error, estimate = np.degrees(error), np.degrees(estimate)
left = error + estimate
print(f"correlation of the kick error with minus the shadow's estimate: {np.corrcoef(error, -estimate)[0, 1]:.3f}")
print("| | median abs | p75 | p90 | p99 | rms |\n|---|---|---|---|---|---|")
for name, x in (("kick error, averaged model as run", error), ("left after adding the shadow's estimate", left)):
    q = np.percentile(np.abs(x), [50, 75, 90, 99])
    print(f"| {name} | " + " | ".join(f"{v:.2f} deg" for v in q) + f" | {math.sqrt(np.mean(x**2)):.2f} deg |")
