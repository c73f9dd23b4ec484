"""Batched fixed-step integration of the full and averaged models: RK4, step size, segments, dispatch.

Free functions compiled with numba. :func:`advance` moves arrays of fish in
place (fin arrays: :mod:`pectoral_gym.model.strokes`; averaged forcing cache:
:mod:`pectoral_gym.model.forcing_cache`):

============  ===========  ======================================================================
array         shape        fields (units)
============  ===========  ======================================================================
``state``     ``(n, 6)``   ``X, Y, psi`` (tank frame; m, m, rad), ``vx, vy, omega`` (body frame;
                           m/s, m/s, rad/s), eq. (19)
``integral``  ``(n, 3)``   running integrals of ``vx, vy, omega`` (m, m, rad), for cycle averages
``coef``      ``(n, 9)``   packed coefficients, ``params.COEF_NAMES`` order (``params.Coef``)
============  ===========  ======================================================================

Time is cut into segments between stroke boundaries (where ``g''`` jumps and
a fin may latch a new pattern, :func:`pectoral_gym.model.strokes.latch`; the averaged
model's corrections of the new half-stroke: :mod:`pectoral_gym.model.stroke_corrections`). The full
model resolves the fin beat with RK4 substeps that land exactly on every
stroke boundary, so the integrator keeps its fourth order across the beat.
The averaged model holds its forcing constant over a segment and sizes its
substeps by the body dynamics' stiffness (:func:`pectoral_gym.model.dynamics.linearised_rate`).
"""

from __future__ import annotations

import enum
import math

import numpy as np

from pectoral_gym.model import forcing_cache as fc
from pectoral_gym.model import strokes as st
from pectoral_gym.model.dynamics import (
    Forcing,
    RateConstants,
    body_accel,
    rate_bound,
    rate_constants,
)
from pectoral_gym.model.fast_step import FAST_ACCURATE_STEP, exponential_substep
from pectoral_gym.model.fast_step import rotate as _rotate
from pectoral_gym.model.jit import PARALLEL_MIN_ITEMS, kernel_pair, kernel_variant, njit
from pectoral_gym.model.ktables import KTables, as_tables
from pectoral_gym.model.params import BodyCoefficients, Coef
from pectoral_gym.model.stroke_corrections import FAST_STEP, start_half_stroke
from pectoral_gym.model.strokes import DURATION, ELAPSED, idle

__all__ = ["ACCURATE_STEP", "ADVANCE_ONE", "STATE_NAMES", "State", "advance", "advance_averaged_one",
           "advance_full_one", "advance_one"]

STATE_NAMES = ("X", "Y", "psi", "vx", "vy", "omega")
#: Column of each state (``state[:, State.PSI]``), generated from :data:`STATE_NAMES`; the integrals
#: of ``vx, vy, omega`` sit in columns 0, 1, 2 of ``integral``.
State = enum.IntEnum("State", {name.upper(): i for i, name in enumerate(STATE_NAMES)})

_EPS = 1e-12
ACCURATE_STEP = 1.5  # averaged model: h * rate bound; RK4 is stable to 2.78, this keeps transients accurate


@njit(inline="always")
def _accel(u, v, w, f: Forcing, b: BodyCoefficients, osc):
    return body_accel(u, v, w, f.fx, f.fy, f.tau, b.m1, b.m2, b.J3, b.c1, b.c2, b.c4, osc)


@njit
def _rk4(state, integral, i, h, f0: Forcing, fm: Forcing, f1: Forcing, body: BodyCoefficients, osc):
    """One RK4 step of eq. (19) for fish ``i``; forcing given at t, t+h/2, t+h.

    ``osc`` [rad/s]: the yaw oscillation of the averaged model's damping
    (:func:`pectoral_gym.model.dynamics.body_accel`); 0 for the full model.
    """
    p0 = state[i, State.PSI]
    _rk4_from(state, integral, i, h, f0, fm, f1, body, osc, math.cos(p0), math.sin(p0))


@njit(inline="always")
def _rk4_from(state, integral, i, h, f0: Forcing, fm: Forcing, f1: Forcing, body: BodyCoefficients, osc, c0, s0):
    """:func:`_rk4` from the heading's ``c0, s0 = cos, sin``; returns those of the heading at the step's end."""
    x0, y0, p0 = state[i, State.X], state[i, State.Y], state[i, State.PSI]
    u0, v0, w0 = state[i, State.VX], state[i, State.VY], state[i, State.OMEGA]
    # stage 1
    k1x, k1y, k1p = u0 * c0 - v0 * s0, u0 * s0 + v0 * c0, w0
    k1u, k1v, k1w = _accel(u0, v0, w0, f0, body, osc)
    # stage 2
    u2, v2, w2 = u0 + 0.5 * h * k1u, v0 + 0.5 * h * k1v, w0 + 0.5 * h * k1w
    c, s = _rotate(c0, s0, 0.5 * h * k1p)
    k2x, k2y, k2p = u2 * c - v2 * s, u2 * s + v2 * c, w2
    k2u, k2v, k2w = _accel(u2, v2, w2, fm, body, osc)
    # stage 3
    u3, v3, w3 = u0 + 0.5 * h * k2u, v0 + 0.5 * h * k2v, w0 + 0.5 * h * k2w
    c, s = _rotate(c0, s0, 0.5 * h * k2p)
    k3x, k3y, k3p = u3 * c - v3 * s, u3 * s + v3 * c, w3
    k3u, k3v, k3w = _accel(u3, v3, w3, fm, body, osc)
    # stage 4
    u4, v4, w4 = u0 + h * k3u, v0 + h * k3v, w0 + h * k3w
    c, s = _rotate(c0, s0, h * k3p)
    k4x, k4y, k4p = u4 * c - v4 * s, u4 * s + v4 * c, w4
    k4u, k4v, k4w = _accel(u4, v4, w4, f1, body, osc)
    h6 = h / 6.0
    state[i, State.X] = x0 + h6 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
    state[i, State.Y] = y0 + h6 * (k1y + 2.0 * k2y + 2.0 * k3y + k4y)
    turn = h6 * (k1p + 2.0 * k2p + 2.0 * k3p + k4p)
    state[i, State.PSI] = p0 + turn
    state[i, State.VX] = u0 + h6 * (k1u + 2.0 * k2u + 2.0 * k3u + k4u)
    state[i, State.VY] = v0 + h6 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
    state[i, State.OMEGA] = w0 + h6 * (k1w + 2.0 * k2w + 2.0 * k3w + k4w)
    # the running integrals are extra RK4 states with derivative (vx, vy, omega)
    integral[i, 0] += h6 * (u0 + 2.0 * u2 + 2.0 * u3 + u4)
    integral[i, 1] += h6 * (v0 + 2.0 * v2 + 2.0 * v3 + v4)
    integral[i, 2] += h6 * (w0 + 2.0 * w2 + 2.0 * w3 + w4)
    return _rotate(c0, s0, turn)


@njit(inline="always")
def _driven(body: BodyCoefficients, forcing: Forcing):
    """Yaw rate and speed a constant forcing drives towards: ``sqrt(|tau| / (c4 J3))``, ``sqrt(|F| / c1)``."""
    return (math.sqrt(abs(forcing.tau) / (body.c4 * body.J3)),
            math.sqrt(math.hypot(forcing.fx, forcing.fy) / max(body.c1, 1e-12)))


@njit
def _stable_step(state, i, rates: RateConstants, driven_omega, driven_speed, osc, dt_max, accurate=ACCURATE_STEP):
    """Averaged model: RK4 step, at most ``dt_max`` and ``h * rate <= accurate`` (default :data:`ACCURATE_STEP`).

    The rate is :func:`pectoral_gym.model.dynamics.linearised_rate` (from the fish's
    precomputed ``rates``) at the larger of the current yaw rate and speed and those
    the forcing drives towards (:func:`_driven`, once per segment), so a fish at
    rest that starts turning does not overshoot.
    """
    omega = max(abs(state[i, State.OMEGA]), driven_omega)
    speed = max(math.sqrt(state[i, State.VX] ** 2 + state[i, State.VY] ** 2), driven_speed)
    rate = rate_bound(speed, omega, osc, rates)
    if rate * dt_max > accurate:
        return accurate / rate
    return dt_max


@njit(inline="always")
def _full_stable_step(state, fins, coef, i, idle0, idle1, body, rates, inertia_constant, fin_offset, h_max):
    """Full model: ``h_max``, shortened where RK4 would leave its accurate range (:func:`_stable_step`).

    The in-beat forcing peaks within the segment, so the rate is taken at the yaw rate and
    speed that each half-stroke's peak force and moment would drive: on ``g = mid - half
    cos(pi s / d)``, ``|g'| <= |half| pi / d`` and ``|g''| <= |half| (pi / d)^2``, so eqs. (16)-(18)
    give ``|f_hx| <= (k + m_p S_p / 2) g'_max^2 + (m_p S_p / 2) g''_max`` (and ``|tau| <= C_p`` times
    that), with each fin's own ``k`` and actual swing (its force factor and servo scale). It never binds at the
    reference steps (``dt_max`` 0.01 s); it keeps the fast
    preset (:data:`pectoral_gym.model.models.FULL_INTEGRATION`) and any larger ``dt_max`` stable.
    """
    force = 0.0
    for f in range(2):
        if idle0 if f == 0 else idle1:
            continue
        rate = math.pi / max(fins[i, f, DURATION], _EPS)
        half = st.actual_amplitude(coef, i, f, 0.5 * abs(fins[i, f, st.ANGLE_TO] - fins[i, f, st.ANGLE_FROM]))
        speed = half * rate  # peak |g'|
        drag_constant = st.fin_drag_constant(coef, i, f)
        force += (drag_constant + inertia_constant) * speed * speed + inertia_constant * speed * rate
    driven_omega = math.sqrt(abs(fin_offset) * force / (body.c4 * body.J3))
    driven_speed = math.sqrt(force / max(body.c1, 1e-12))
    return _stable_step(state, i, rates, driven_omega, driven_speed, 0.0, h_max)


@njit(inline="always")
def _constant_forcing_segment(state, integral, i, seg, body, rates, forcing, osc, dt_max, fast, accurate):
    """Integrate fish ``i`` over a segment of constant forcing.

    Equal RK4 substeps to the segment's end, re-sized as the state's stiffness changes (:func:`_stable_step`,
    ``h * rate <= accurate``). ``fast``: the averaged model's fast step's substeps instead
    (:func:`pectoral_gym.model.fast_step.exponential_substep`, which sizes each itself; the heading's ``cos, sin``
    are carried from substep to substep).
    """
    t_seg = seg
    driven_omega, driven_speed = _driven(body, forcing)
    c = s = 0.0
    if fast:
        c, s = math.cos(state[i, State.PSI]), math.sin(state[i, State.PSI])
    while t_seg > _EPS:
        if fast:
            c, s, h = exponential_substep(state, integral, i, t_seg, forcing, body, rates, osc, driven_omega,
                                          driven_speed, c, s, dt_max, accurate)
        else:
            h_ok = _stable_step(state, i, rates, driven_omega, driven_speed, osc, dt_max, accurate)
            h = t_seg / max(1, int(math.ceil(t_seg / h_ok - 1e-9)))
            _rk4(state, integral, i, h, forcing, forcing, forcing, body, osc)
        t_seg -= h


AVERAGED = True  # the model of a build of _advance_model (kernel_variant binds it): a constant to numba


def _advance_model(i, state, fins, cache, pending, integral, coef, duration, dt_max, min_substeps, averaged, mode,
                   corrections, packed_tables):
    """Advance fish ``i`` of the model :data:`AVERAGED` by ``duration`` s, segment by segment between stroke boundaries.

    Compiled as :func:`advance_averaged_one` and :func:`advance_full_one` (``averaged`` is not read): numba
    prunes the branches of the other model before it inlines and types them, so neither compiles the
    other's code.
    """
    tables = as_tables(packed_tables)
    body = BodyCoefficients(coef[i, Coef.M1], coef[i, Coef.M2], coef[i, Coef.J3],
                            coef[i, Coef.C1], coef[i, Coef.C2], coef[i, Coef.C4])
    drag_right, drag_left = st.fin_drag_constant(coef, i, 0), st.fin_drag_constant(coef, i, 1)
    inertia_constant = coef[i, Coef.FIN_INERTIA_CONSTANT]
    fin_offset = coef[i, Coef.FIN_OFFSET]
    # each fin's servo map: the forces see its actual angle (the stroke state keeps the commanded one)
    offset0, scale0 = coef[i, st.FIN_ANGLE_OFFSET[0]], coef[i, st.FIN_ANGLE_SCALE[0]]
    offset1, scale1 = coef[i, st.FIN_ANGLE_OFFSET[1]], coef[i, st.FIN_ANGLE_SCALE[1]]
    rates = rate_constants(body.m1, body.m2, body.J3, body.c1, body.c2, body.c4)
    fast = AVERAGED and (corrections & FAST_STEP) != 0
    accurate = FAST_ACCURATE_STEP if fast else ACCURATE_STEP
    t_left = duration
    while t_left > _EPS:
        # A fin at rest that stays at rest never ends a segment: its stroke clock must
        # not cut the other fin's integration into phase-dependent pieces.
        idle0 = idle(fins, pending, i, 0)
        idle1 = idle(fins, pending, i, 1)
        if not idle0 and fins[i, 0, ELAPSED] >= fins[i, 0, DURATION] - _EPS:
            start_half_stroke(fins, cache, pending, i, 0, coef, AVERAGED, mode, tables, corrections)
        if not idle1 and fins[i, 1, ELAPSED] >= fins[i, 1, DURATION] - _EPS:
            start_half_stroke(fins, cache, pending, i, 1, coef, AVERAGED, mode, tables, corrections)
        rem0 = np.inf if idle0 else fins[i, 0, DURATION] - fins[i, 0, ELAPSED]
        rem1 = np.inf if idle1 else fins[i, 1, DURATION] - fins[i, 1, ELAPSED]
        seg = min(t_left, rem0, rem1)
        if AVERAGED:
            fx = cache[i, 0, fc.AVG_FX] + cache[i, 1, fc.AVG_FX]
            fy = cache[i, 0, fc.AVG_FY] + cache[i, 1, fc.AVG_FY]
            tau = cache[i, 0, fc.AVG_TAU] + cache[i, 1, fc.AVG_TAU]
            if corrections:  # each fin's, evaluated when it latched (stroke_corrections.start_half_stroke)
                for f in range(2):
                    fx, fy, tau = fx + cache[i, f, fc.TR_FX], fy + cache[i, f, fc.TR_FY], tau + cache[i, f, fc.TR_TAU]
            forcing = Forcing(fx, fy, tau)
            osc = fc.yaw_oscillation(fins, cache, i, 0.5 * seg, idle0, idle1, fast)
            _constant_forcing_segment(state, integral, i, seg, body, rates, forcing, osc, dt_max, fast, accurate)
        else:
            h_max = dt_max
            if not idle0:
                h_max = min(h_max, fins[i, 0, DURATION] / min_substeps)
            if not idle1:
                h_max = min(h_max, fins[i, 1, DURATION] / min_substeps)
            h_max = _full_stable_step(state, fins, coef, i, idle0, idle1, body, rates, inertia_constant, fin_offset,
                                      h_max)
            n_sub = max(1, int(math.ceil(seg / h_max - 1e-9)))
            h = seg / n_sub
            # the forces at t, t + h/2, t + h of every substep: each fin's phase rotated by h/2 each time
            p0 = st.stroke_phase(fins, i, 0, 0.5 * h, 0.0, offset0, scale0)
            p1 = st.stroke_phase(fins, i, 1, 0.5 * h, 0.0, offset1, scale1)
            f0 = Forcing(*st.phase_forcing(p0, p1, drag_right, drag_left, inertia_constant, fin_offset))
            for _ in range(n_sub):
                p0, p1 = st.advance_phase(p0), st.advance_phase(p1)
                fm = Forcing(*st.phase_forcing(p0, p1, drag_right, drag_left, inertia_constant, fin_offset))
                p0, p1 = st.advance_phase(p0), st.advance_phase(p1)
                f1 = Forcing(*st.phase_forcing(p0, p1, drag_right, drag_left, inertia_constant, fin_offset))
                _rk4(state, integral, i, h, f0, fm, f1, body, 0.0)
                f0 = f1
        if not idle0:  # the strokes actually swept, for the fin work (both models)
            fins[i, 0, st.SWEPT] += st.swept_cube(fins, i, 0, seg, fast)
        if not idle1:
            fins[i, 1, st.SWEPT] += st.swept_cube(fins, i, 1, seg, fast)
        if rem0 - seg <= _EPS:
            fins[i, 0, ELAPSED] = fins[i, 0, DURATION]  # exactly on the boundary
        elif not idle0:
            fins[i, 0, ELAPSED] += seg
        if rem1 - seg <= _EPS:
            fins[i, 1, ELAPSED] = fins[i, 1, DURATION]
        elif not idle1:
            fins[i, 1, ELAPSED] += seg
        t_left -= seg


#: :func:`advance_one` of the averaged model (eq. 25), compiled without the full model's code.
advance_averaged_one = kernel_variant(_advance_model, "advance_averaged_one", {"AVERAGED": True})
#: :func:`advance_one` of the full model (eq. 19), compiled without the averaged model's code.
advance_full_one = kernel_variant(_advance_model, "advance_full_one", {"AVERAGED": False})


@njit
def advance_one(i, state, fins, cache, pending, integral, coef, duration, dt_max, min_substeps, averaged, mode,
                corrections, packed_tables):
    """Advance fish ``i`` by ``duration`` seconds, segment by segment between stroke boundaries.

    The model is chosen at run time by ``averaged``, so both are compiled: a caller that knows its model
    calls :data:`ADVANCE_ONE` ``[averaged]`` instead, which compiles that model's alone.
    """
    if averaged:
        advance_averaged_one(i, state, fins, cache, pending, integral, coef, duration, dt_max, min_substeps, True,
                             mode, corrections, packed_tables)
    else:
        advance_full_one(i, state, fins, cache, pending, integral, coef, duration, dt_max, min_substeps, False,
                         mode, corrections, packed_tables)


#: ``averaged`` -> the kernel that advances one fish of that model (same arguments as :func:`advance_one`).
ADVANCE_ONE = {True: advance_averaged_one, False: advance_full_one}
_ADVANCE = {averaged: kernel_pair(
    kernel,
    "state, fins, cache, pending, integral, coef, duration, dt_max, min_substeps, averaged, mode, corrections, "
    "packed_tables",
) for averaged, kernel in ADVANCE_ONE.items()}


def advance(
    state: np.ndarray,
    fins: np.ndarray,
    cache: np.ndarray,
    pending: np.ndarray,
    integral: np.ndarray,
    coef: np.ndarray,
    duration: float,
    dt_max: float,
    min_substeps: int,
    averaged: bool,
    mode: int,
    tables: KTables,
    corrections: int = 0,
) -> None:
    """Advance every fish by ``duration`` seconds in place (see module docstring).

    Args:
        state, integral, coef: Batched arrays (module docstring).
        fins, pending: Fin half-strokes and commanded patterns (:mod:`pectoral_gym.model.strokes`).
        cache: Averaged forcing cache (:mod:`~pectoral_gym.model.forcing_cache`); read and written only if ``averaged``.
        duration: Time to advance [s].
        dt_max: Largest RK4 substep [s].
        min_substeps: Full model: least number of substeps per half-stroke.
        averaged: Integrate the averaged model (eq. 25) instead of the full one (eq. 19).
        mode: Averaged forcing form (``averaging.EXACT`` or ``averaging.TAYLOR``).
        tables: Scaling functions (``kfunctions.ScalingFunctions.kernel_arrays()``), or ``tuple()`` of them.
        corrections: Averaged model: a sum of :data:`~pectoral_gym.model.stroke_corrections.TRANSITIONS`
            (each transitional half-stroke's forcing beyond the regular half-stroke, ``docs/model.md`` 3.7)
            and :data:`~pectoral_gym.model.stroke_corrections.RIPPLE_OFFSETS` (the beat-mean ripple
            offset, 3.8); see :func:`pectoral_gym.model.stroke_corrections.corrections`.
    """
    kernels = _ADVANCE[bool(averaged)]  # the model's own kernels only
    kernel = kernels.parallel if state.shape[0] >= PARALLEL_MIN_ITEMS else kernels.serial
    kernel(state, fins, cache, pending, integral, coef, float(duration), float(dt_max), float(min_substeps),
           bool(averaged), int(mode), int(corrections),
           tuple(tables))  # a plain tuple is faster to dispatch (ktables.as_tables)
