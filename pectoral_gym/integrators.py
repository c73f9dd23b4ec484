"""Batched fixed-step integrators for the full and averaged models.

Free functions compiled with numba. They advance arrays of fish in place:

* ``state``    ``(n, 6)``: ``X, Y, psi`` (tank frame, m, m, rad) and ``vx, vy, omega``
  (body frame, m/s, m/s, rad/s), eq. (19).
* ``fins``     ``(n, 2, FIN_FIELDS)``: each fin's current half-stroke (index 0 right, 1 left).
* ``pending``  ``(n, 2, 4)``: the commanded ``(bias, amplitude, period, ratio)`` per fin.
* ``integral`` ``(n, 3)``: running integrals of ``vx, vy, omega`` (for cycle averages).

**Parameter-change rule.** A fin latches its commanded parameters only at a
turning point of its stroke (where ``g' = 0``): at the end of the current
half-stroke, or at once if the fin is not moving. The next half-stroke then
runs from the current angle to the new pattern's turning point
(``bias + amplitude`` for a power stroke, ``bias - amplitude`` for recovery)
with the new pattern's stroke duration. The fin angle and rate stay
continuous; with constant parameters the motion is exactly eq. (21). The
averaged model follows the same schedule and switches its averaged forcing
at the same instants.

The full model resolves the fin beat with RK4 substeps that land exactly on
every stroke boundary (where ``g''`` jumps), so the integrator keeps its
fourth order across the beat.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from pectoral_gym.averaging import averaged_body_accel, averaged_fin_forcing, yaw_oscillation_phasor
from pectoral_gym.dynamics import fin_force_right, stroke_kinematics

__all__ = [
    "FIN_FIELDS",
    "ELAPSED", "DURATION", "ANGLE_FROM", "ANGLE_TO", "POWER",
    "BIAS", "AMPLITUDE", "PERIOD", "RATIO", "AVG_FX", "AVG_FY", "AVG_TAU", "OSC_COS", "OSC_SIN", "CACHED",
    "init_fins", "command_fins", "advance", "fin_angles",
]

# Fields of the fin array.
ELAPSED, DURATION, ANGLE_FROM, ANGLE_TO, POWER = 0, 1, 2, 3, 4
BIAS, AMPLITUDE, PERIOD, RATIO = 5, 6, 7, 8
AVG_FX, AVG_FY, AVG_TAU = 9, 10, 11  # scaled averaged forcing of the active pattern
OSC_COS, OSC_SIN = 12, 13  # phasor of the yaw-rate oscillation the active pattern drives (signed by side)
CACHED = 14  # 1 when fields AVG_FX..OSC_SIN hold the values of the pattern in BIAS..RATIO
FIN_FIELDS = 15

_EPS = 1e-12
_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}
_SIDE = (1.0, -1.0)  # right fin, left fin (mirror image)


# The kernels index the batched arrays directly (no per-fish views or temporary
# arrays): views and allocations touch shared reference counts, which serialises
# the threads of the parallel kernel.


@nb.njit(**_JIT)
def _latch(fins, pending, i, f, coef, mode, kfun):
    """Start the next half-stroke of fin ``f`` of fish ``i`` with its commanded parameters."""
    bias, amp, period, ratio = pending[i, f, 0], pending[i, f, 1], pending[i, f, 2], pending[i, f, 3]
    power = 1.0 - fins[i, f, POWER]
    fins[i, f, ANGLE_FROM] = fins[i, f, ANGLE_TO]
    if power > 0.5:
        fins[i, f, ANGLE_TO] = bias + amp
        fins[i, f, DURATION] = period / (ratio + 1.0)  # eq. (21), power stroke
    else:
        fins[i, f, ANGLE_TO] = bias - amp
        fins[i, f, DURATION] = ratio * period / (ratio + 1.0)  # eq. (21), recovery
    fins[i, f, ELAPSED] = 0.0
    fins[i, f, POWER] = power
    if (fins[i, f, CACHED] == 1.0 and fins[i, f, BIAS] == bias and fins[i, f, AMPLITUDE] == amp
            and fins[i, f, PERIOD] == period and fins[i, f, RATIO] == ratio):
        return  # same pattern as the last half-stroke: its averaged forcing is still valid
    fins[i, f, BIAS] = bias
    fins[i, f, AMPLITUDE] = amp
    fins[i, f, PERIOD] = period
    fins[i, f, RATIO] = ratio
    fx, fy, tau = averaged_fin_forcing(bias, amp, period, ratio, _SIDE[f], coef[i], mode, kfun)
    fins[i, f, AVG_FX] = fx
    fins[i, f, AVG_FY] = fy
    fins[i, f, AVG_TAU] = tau
    pc, ps = yaw_oscillation_phasor(bias, amp, period, ratio, kfun)
    fins[i, f, OSC_COS] = _SIDE[f] * pc  # the left fin's yaw oscillation is the mirror image
    fins[i, f, OSC_SIN] = _SIDE[f] * ps
    fins[i, f, CACHED] = 1.0


@nb.njit(**_JIT)
def _yaw_oscillation(fins, i, offset, idle0, idle1):
    """Amplitude [rad/s] of the yaw-rate oscillation both fins drive, ``offset`` s into the segment.

    Each fin's oscillation is ``Re(P e^{i theta})`` with its phasor ``P`` and
    its beat phase ``theta = 2 pi t / T_p`` (``t`` from the start of its power
    stroke); the two add as phasors. Fins beating in phase with the same
    pattern cancel (straight swimming has no yaw oscillation); fins with
    different periods drift through all relative phases.
    """
    re = 0.0
    im = 0.0
    for f in range(2):
        if (idle0 if f == 0 else idle1) or fins[i, f, ANGLE_FROM] == fins[i, f, ANGLE_TO]:
            continue
        if fins[i, f, OSC_COS] == 0.0 and fins[i, f, OSC_SIN] == 0.0:
            continue  # no yaw-oscillation data (or no stroke): skip the trigonometry
        period = fins[i, f, PERIOD]
        t = fins[i, f, ELAPSED] + offset
        if fins[i, f, POWER] < 0.5:
            t += period / (fins[i, f, RATIO] + 1.0)  # recovery follows the power stroke
        theta = 2.0 * math.pi * t / period
        c, s = math.cos(theta), math.sin(theta)
        re += fins[i, f, OSC_COS] * c - fins[i, f, OSC_SIN] * s
        im += fins[i, f, OSC_COS] * s + fins[i, f, OSC_SIN] * c
    return math.sqrt(re * re + im * im)


@nb.njit(**_JIT)
def _idle(fins, pending, i, f):
    """True for a fin that holds still and is commanded to hold still at the same angle."""
    return (
        fins[i, f, ANGLE_FROM] == fins[i, f, ANGLE_TO]
        and pending[i, f, 1] == 0.0
        and pending[i, f, 0] == fins[i, f, ANGLE_TO]
    )


@nb.njit(**_JIT)
def _fin_forcing(fins, i, offset, drag_constant, inertia_constant, fin_offset):
    """Total blade-element force and moment of both fins, ``offset`` s into the segment."""
    fx_total = 0.0
    fy_total = 0.0
    tau_total = 0.0
    for f in range(2):
        if fins[i, f, ANGLE_FROM] == fins[i, f, ANGLE_TO]:
            continue  # a still fin exerts no force (g' = g'' = 0)
        g, gd, gdd = stroke_kinematics(
            fins[i, f, ELAPSED] + offset, fins[i, f, DURATION], fins[i, f, ANGLE_FROM], fins[i, f, ANGLE_TO]
        )
        fx, fy = fin_force_right(g, gd, gdd, drag_constant, inertia_constant)
        side = _SIDE[f]
        fx_total += fx
        fy_total += side * fy  # left fin mirrors y
        tau_total += side * fin_offset * fx  # eq. (18): tau_R = +C_p f_hx, tau_L = -C_p f_hx
    return fx_total, fy_total, tau_total


@nb.njit(**_JIT)
def _rotate(c0, s0, delta):
    """``cos, sin`` of ``psi0 + delta`` from those of ``psi0``.

    RK4 stages move the heading by at most ``h |omega|``, a small angle: a
    short series (error below 1e-12 for ``|delta| <= 0.1``) replaces three of
    the four ``sin/cos`` pairs per step.
    """
    if abs(delta) > 0.1:
        cd, sd = math.cos(delta), math.sin(delta)
    else:
        d2 = delta * delta
        cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0 - d2 / 720.0))
        sd = delta * (1.0 - d2 * (1.0 / 6.0 - d2 / 120.0))
    return c0 * cd - s0 * sd, s0 * cd + c0 * sd


@nb.njit(**_JIT)
def _rk4(state, integral, i, h, f0x, f0y, f0t, fmx, fmy, fmt, f1x, f1y, f1t, m1, m2, j3, c1, c2, c4, osc):
    """One RK4 step of eq. (19) for fish ``i``; forcing given at t, t+h/2, t+h.

    ``osc`` [rad/s]: the yaw oscillation of the averaged model's damping
    (:func:`pectoral_gym.averaging.averaged_body_accel`); 0 for the full model.
    """
    x0, y0, p0, u0, v0, w0 = state[i, 0], state[i, 1], state[i, 2], state[i, 3], state[i, 4], state[i, 5]
    c0, s0 = math.cos(p0), math.sin(p0)
    # stage 1
    k1x, k1y, k1p = u0 * c0 - v0 * s0, u0 * s0 + v0 * c0, w0
    k1u, k1v, k1w = averaged_body_accel(u0, v0, w0, f0x, f0y, f0t, m1, m2, j3, c1, c2, c4, osc)
    # stage 2
    u2, v2, w2 = u0 + 0.5 * h * k1u, v0 + 0.5 * h * k1v, w0 + 0.5 * h * k1w
    c, s = _rotate(c0, s0, 0.5 * h * k1p)
    k2x, k2y, k2p = u2 * c - v2 * s, u2 * s + v2 * c, w2
    k2u, k2v, k2w = averaged_body_accel(u2, v2, w2, fmx, fmy, fmt, m1, m2, j3, c1, c2, c4, osc)
    # stage 3
    u3, v3, w3 = u0 + 0.5 * h * k2u, v0 + 0.5 * h * k2v, w0 + 0.5 * h * k2w
    c, s = _rotate(c0, s0, 0.5 * h * k2p)
    k3x, k3y, k3p = u3 * c - v3 * s, u3 * s + v3 * c, w3
    k3u, k3v, k3w = averaged_body_accel(u3, v3, w3, fmx, fmy, fmt, m1, m2, j3, c1, c2, c4, osc)
    # stage 4
    u4, v4, w4 = u0 + h * k3u, v0 + h * k3v, w0 + h * k3w
    c, s = _rotate(c0, s0, h * k3p)
    k4x, k4y, k4p = u4 * c - v4 * s, u4 * s + v4 * c, w4
    k4u, k4v, k4w = averaged_body_accel(u4, v4, w4, f1x, f1y, f1t, m1, m2, j3, c1, c2, c4, osc)
    h6 = h / 6.0
    state[i, 0] = x0 + h6 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
    state[i, 1] = y0 + h6 * (k1y + 2.0 * k2y + 2.0 * k3y + k4y)
    state[i, 2] = p0 + h6 * (k1p + 2.0 * k2p + 2.0 * k3p + k4p)
    state[i, 3] = u0 + h6 * (k1u + 2.0 * k2u + 2.0 * k3u + k4u)
    state[i, 4] = v0 + h6 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
    state[i, 5] = w0 + h6 * (k1w + 2.0 * k2w + 2.0 * k3w + k4w)
    # the running integrals are extra RK4 states with derivative (vx, vy, omega)
    integral[i, 0] += h6 * (u0 + 2.0 * u2 + 2.0 * u3 + u4)
    integral[i, 1] += h6 * (v0 + 2.0 * v2 + 2.0 * v3 + v4)
    integral[i, 2] += h6 * (w0 + 2.0 * w2 + 2.0 * w3 + w4)


@nb.njit(**_JIT)
def _stable_step(state, i, m1, m2, j3, c1, c4, fx, fy, tau, osc, dt_max):
    """Averaged model: RK4 step, at most ``dt_max`` and well inside the stability limit.

    The stiffest mode is the yaw damping ``-c4 omega|omega|`` (rate ``2 c4 |omega|``),
    then the body drag (rate ~ ``2 c1 |V| / m``). Rates are taken at the larger
    of the current value and the value the forcing drives towards
    (``omega* = sqrt(|tau| / (c4 J3))``, ``V* = sqrt(|F| / c1)``), so a fish at
    rest that starts turning does not overshoot. ``h * rate <= 1.5`` keeps
    RK4 (stable to 2.78) accurate on the transients. The oscillation-averaged
    damping's rate ``2 c4 mean|omega + osc sin|`` is at most ``2 c4 (|omega| + 2 osc / pi)``.
    """
    omega = max(abs(state[i, 5]), math.sqrt(abs(tau) / (c4 * j3))) + 2.0 / math.pi * osc
    speed = max(math.sqrt(state[i, 3] ** 2 + state[i, 4] ** 2), math.sqrt(math.hypot(fx, fy) / max(c1, 1e-12)))
    rate = 2.0 * c4 * omega + 3.0 * c1 * speed / min(m1, m2) + omega
    if rate * dt_max > 1.5:
        return 1.5 / rate
    return dt_max


@nb.njit(**_JIT)
def _advance_one(
    i, state, fins, pending, integral, coef, duration, dt_max, min_substeps, averaged, mode, kfun
):
    """Advance fish ``i`` by ``duration`` seconds, segment by segment between stroke boundaries."""
    m1, m2, j3, c1, c2, c4 = coef[i, 0], coef[i, 1], coef[i, 2], coef[i, 3], coef[i, 4], coef[i, 5]
    drag_constant, inertia_constant, fin_offset = coef[i, 6], coef[i, 7], coef[i, 8]
    t_left = duration
    while t_left > _EPS:
        # A fin at rest that stays at rest never ends a segment: its stroke clock must
        # not cut the other fin's integration into phase-dependent pieces.
        idle0 = _idle(fins, pending, i, 0)
        idle1 = _idle(fins, pending, i, 1)
        if not idle0 and fins[i, 0, ELAPSED] >= fins[i, 0, DURATION] - _EPS:
            _latch(fins, pending, i, 0, coef, mode, kfun)
        if not idle1 and fins[i, 1, ELAPSED] >= fins[i, 1, DURATION] - _EPS:
            _latch(fins, pending, i, 1, coef, mode, kfun)
        rem0 = np.inf if idle0 else fins[i, 0, DURATION] - fins[i, 0, ELAPSED]
        rem1 = np.inf if idle1 else fins[i, 1, DURATION] - fins[i, 1, ELAPSED]
        seg = min(t_left, rem0, rem1)
        if averaged:
            fx = fins[i, 0, AVG_FX] + fins[i, 1, AVG_FX]
            fy = fins[i, 0, AVG_FY] + fins[i, 1, AVG_FY]
            tau = fins[i, 0, AVG_TAU] + fins[i, 1, AVG_TAU]
            osc = _yaw_oscillation(fins, i, 0.5 * seg, idle0, idle1)
            t_seg = seg
            while t_seg > _EPS:
                # equal substeps to the segment end, re-sized as the state's stiffness changes
                h_ok = _stable_step(state, i, m1, m2, j3, c1, c4, fx, fy, tau, osc, dt_max)
                h = t_seg / max(1, int(math.ceil(t_seg / h_ok - 1e-9)))
                _rk4(state, integral, i, h, fx, fy, tau, fx, fy, tau, fx, fy, tau, m1, m2, j3, c1, c2, c4, osc)
                t_seg -= h
        else:
            h_max = dt_max
            if not idle0:
                h_max = min(h_max, fins[i, 0, DURATION] / min_substeps)
            if not idle1:
                h_max = min(h_max, fins[i, 1, DURATION] / min_substeps)
            n_sub = max(1, int(math.ceil(seg / h_max - 1e-9)))
            h = seg / n_sub
            f0x, f0y, f0t = _fin_forcing(fins, i, 0.0, drag_constant, inertia_constant, fin_offset)
            for k in range(n_sub):
                fmx, fmy, fmt = _fin_forcing(fins, i, (k + 0.5) * h, drag_constant, inertia_constant, fin_offset)
                f1x, f1y, f1t = _fin_forcing(fins, i, (k + 1.0) * h, drag_constant, inertia_constant, fin_offset)
                _rk4(state, integral, i, h, f0x, f0y, f0t, fmx, fmy, fmt, f1x, f1y, f1t, m1, m2, j3, c1, c2, c4, 0.0)
                f0x, f0y, f0t = f1x, f1y, f1t
        if rem0 - seg <= _EPS:
            fins[i, 0, ELAPSED] = fins[i, 0, DURATION]  # exactly on the boundary
        elif not idle0:
            fins[i, 0, ELAPSED] += seg
        if rem1 - seg <= _EPS:
            fins[i, 1, ELAPSED] = fins[i, 1, DURATION]
        elif not idle1:
            fins[i, 1, ELAPSED] += seg
        t_left -= seg


@nb.njit(**_JIT)
def _advance_serial(
    state, fins, pending, integral, coef, duration, dt_max, min_substeps, averaged, mode, kfun
):
    for i in range(state.shape[0]):
        _advance_one(
            i, state, fins, pending, integral, coef, duration, dt_max, min_substeps, averaged, mode, kfun
        )


@nb.njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def _advance_parallel(
    state, fins, pending, integral, coef, duration, dt_max, min_substeps, averaged, mode, kfun
):
    for i in nb.prange(state.shape[0]):
        _advance_one(
            i, state, fins, pending, integral, coef, duration, dt_max, min_substeps, averaged, mode, kfun
        )


PARALLEL_MIN_FISH = 64  # below this, thread start-up costs more than it saves


def advance(
    state: np.ndarray,
    fins: np.ndarray,
    pending: np.ndarray,
    integral: np.ndarray,
    coef: np.ndarray,
    duration: float,
    dt_max: float,
    min_substeps: int,
    averaged: bool,
    mode: int,
    kfun: tuple,
) -> None:
    """Advance every fish by ``duration`` seconds in place (see module docstring).

    Args:
        state, fins, pending, integral: Batched arrays (module docstring).
        coef: ``(n, 9)`` packed coefficients (``params.COEF_NAMES``).
        duration: Time to advance [s].
        dt_max: Largest RK4 substep [s].
        min_substeps: Full model: least number of substeps per half-stroke.
        averaged: Integrate the averaged model (eq. 25) instead of the full one (eq. 19).
        mode: Averaged forcing form (``averaging.EXACT`` or ``averaging.TAYLOR``).
        kfun: Scaling functions (``kfunctions.ScalingFunctions.kernel_arrays()``).
    """
    kernel = _advance_parallel if state.shape[0] >= PARALLEL_MIN_FISH else _advance_serial
    kernel(state, fins, pending, integral, coef, float(duration), float(dt_max), float(min_substeps),
           bool(averaged), int(mode), kfun)


@nb.njit(**_JIT)
def command_fins(fins, pending, new, mask):
    """Store new commanded patterns ``new`` ``(n, 2, 4)`` for the fish where ``mask``.

    A fin that is not moving (its stroke starts and ends at the same angle)
    latches at once: its current stroke is marked finished, and it starts with
    a power stroke.
    """
    for i in range(new.shape[0]):
        if not mask[i]:
            continue
        for f in range(2):
            for j in range(4):
                pending[i, f, j] = new[i, f, j]
            if fins[i, f, ANGLE_FROM] == fins[i, f, ANGLE_TO]:
                fins[i, f, ELAPSED] = fins[i, f, DURATION]
                fins[i, f, POWER] = 0.0


def init_fins(fins: np.ndarray, pending: np.ndarray, beats: np.ndarray, index: np.ndarray | None = None) -> None:
    """Put the fins of the fish in ``index`` (all if ``None``) at the start of a power stroke of ``beats``.

    ``beats`` has one ``(2, 4)`` row per selected fish.

    The fin sits at ``bias - amplitude`` with zero rate; the first half-stroke
    latches the pattern when the model first advances.
    """
    idx = slice(None) if index is None else index
    b = beats  # one row per selected fish
    fins[idx] = 0.0
    fins[idx, :, ANGLE_TO] = b[..., 0] - b[..., 1]
    fins[idx, :, ANGLE_FROM] = fins[idx, :, ANGLE_TO]
    fins[idx, :, DURATION] = 0.0  # finished: latch at the first advance
    fins[idx, :, POWER] = 0.0  # so the first stroke is a power stroke
    fins[idx, :, BIAS:RATIO + 1] = b
    pending[idx] = b


@nb.njit(**_JIT)
def fin_angles(fins):
    """Current fin angles ``(n, 2)`` [rad] and rates [rad/s]."""
    n = fins.shape[0]
    angle = np.empty((n, 2))
    rate = np.empty((n, 2))
    for i in range(n):
        for f in range(2):
            if fins[i, f, DURATION] <= 0.0:
                angle[i, f] = fins[i, f, ANGLE_TO]
                rate[i, f] = 0.0
            else:
                g, gd, _ = stroke_kinematics(
                    fins[i, f, ELAPSED], fins[i, f, DURATION], fins[i, f, ANGLE_FROM], fins[i, f, ANGLE_TO]
                )
                angle[i, f] = g
                rate[i, f] = gd
    return angle, rate
