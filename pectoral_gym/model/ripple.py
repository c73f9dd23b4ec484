"""Yaw-oscillation gain of a transitional half-stroke (``docs/model.md`` section 3.9).

The averaged model's yaw damping averages ``omega|omega|`` over the latched
pattern's in-beat yaw oscillation (3.6), a phasor identified on regular beats.
A transitional half-stroke (3.7) sweeps from wherever the fin was, often much
farther or faster than the pattern's own stroke, and its force ripple is
larger than the regular half-stroke's. The yaw damping time ``1 / (2 c4 |omega|)``
(Table 1: 26 ms at 1 rad/s, 88 ms at 0.3 rad/s) is short against most half-strokes
(0.08-1.7 s in the envs' ranges), so the yaw rate follows the moment nearly
quasi-statically, ``omega ~ sqrt(|tau| / (c4 J3))``: its ripple grows with the square
root of the moment's ripple (the quasi-static limit; the gain takes it as exact). The gain scales the
fin's phasor over the half-stroke by::

    G = (S_swept / S_regular)^(1/4),   S = mean over the half-stroke of (f_hx - F)^2

with ``F`` the latched pattern's exact cycle-mean ``f_hx`` and ``S_regular`` that
of the pattern's own half-stroke of the same kind (power or recovery), so
``G = 1`` on every regular half-stroke and the model is unchanged at periodic
steady state (K, Table 4 and the held-out figures do not move).
"""

from __future__ import annotations

import math

import numpy as np

from pectoral_gym.model.averaging import half_stroke_mean_force
from pectoral_gym.model.dynamics import fin_force_at
from pectoral_gym.model.fast_step import sin_cos_half_turn, sin_cos_of_angle
from pectoral_gym.model.jit import njit

__all__ = ["FAST_RIPPLE_NODES", "RIPPLE_NODES", "half_stroke_ripple_square", "transitional_oscillation_gain"]

#: Gauss-Legendre nodes on the half-stroke phase ``[0, pi]``. The integrand is analytic in the phase:
#: 12 nodes integrate it to 1e-5 (relative; the worst is a full 180 deg sweep), 3e-6 in ``G``
#: (tests/test_stroke_ripple.py); each pair of nodes costs one ``sin/cos`` (those of the phase are tabulated).
RIPPLE_NODES = 12
#: The nodes of the averaged model's fast step (:mod:`pectoral_gym.model.fast_step`): ``G`` within 3.3e-4
#: (relative) of the 12 nodes' over the envs' patterns and transitions (tests/test_fast_step.py).
FAST_RIPPLE_NODES = 8


def _node_tables(nodes: int):
    """``sin, cos`` of the Gauss-Legendre phases on ``[0, pi]`` and the weights of the mean over it."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    phase = (x + 1.0) * 0.5 * math.pi
    return np.sin(phase), np.cos(phase), w * 0.5  # (pi / 2) from the change of variable, 1 / pi for the mean


_SIN_PHASE, _COS_PHASE, _WEIGHT = _node_tables(RIPPLE_NODES)
_FAST_SIN_PHASE, _FAST_COS_PHASE, _FAST_WEIGHT = _node_tables(FAST_RIPPLE_NODES)


@njit
def half_stroke_ripple_square(angle_from: float, angle_to: float, duration: float, drag_constant: float,
                              inertia_constant: float, mean_force: float, fast: bool = False) -> float:
    """Mean [N^2] of ``(f_hx - mean_force)^2`` over one half-cosine half-stroke of the right fin.

    ``g = mid - half cos(phi)``, ``phi = pi s / d`` (:func:`pectoral_gym.model.dynamics.stroke_kinematics`);
    ``f_hx`` is eq. (16) with the drag of eq. (13) and the inertial term of eq. (15)
    (:func:`pectoral_gym.model.dynamics.fin_force_at`), evaluated at :data:`RIPPLE_NODES` phases.
    ``fast``: the fast step's :data:`FAST_RIPPLE_NODES`, ``sin`` and ``cos`` (:mod:`pectoral_gym.model.fast_step`).
    """
    if fast:
        return _ripple_square(angle_from, angle_to, duration, drag_constant, inertia_constant, mean_force,
                              _FAST_SIN_PHASE, _FAST_COS_PHASE, _FAST_WEIGHT, True)
    return _ripple_square(angle_from, angle_to, duration, drag_constant, inertia_constant, mean_force,
                          _SIN_PHASE, _COS_PHASE, _WEIGHT, False)


@njit(inline="always")
def _ripple_square(angle_from, angle_to, duration, drag_constant, inertia_constant, mean_force, sin_phase, cos_phase,
                   weight, fast):
    """:func:`half_stroke_ripple_square` on the given nodes (``sin, cos`` of the phases, weights)."""
    mid = 0.5 * (angle_from + angle_to)
    half = 0.5 * (angle_to - angle_from)
    rate = math.pi / duration
    if fast:
        sm, cm = sin_cos_of_angle(mid)
    else:
        sm, cm = math.sin(mid), math.cos(mid)
    total = 0.0
    # The nodes pair up as phi and pi - phi (same sin, opposite cos, equal weights): g = mid -+ half cos(phi)
    # share sin/cos(half cos(phi)), so a pair costs one sin/cos.
    for j in range(sin_phase.shape[0] // 2):
        sp, cp = sin_phase[j], cos_phase[j]
        if fast:  # |half cos(phi)| <= |half| <= pi/2
            sh, ch = sin_cos_half_turn(half * cp)
        else:
            sh, ch = math.sin(half * cp), math.cos(half * cp)
        gd = half * rate * sp
        gdd = half * rate * rate * cp
        for sign in (1.0, -1.0):  # phi, then pi - phi
            sg = sm * ch - sign * cm * sh  # sin(mid - sign half cos(phi))
            cg = cm * ch + sign * sm * sh
            fx, _ = fin_force_at(sg, cg, gd, sign * gdd, drag_constant, inertia_constant)  # eq. (16)
            total += weight[j] * (fx - mean_force) ** 2
    return total


@njit
def transitional_oscillation_gain(angle_from: float, angle_to: float, duration: float, power: bool, bias: float,
                                  amplitude: float, period: float, ratio: float, drag_constant: float,
                                  inertia_constant: float, fast: bool = False) -> float:
    """Gain ``G`` (module docstring) of the half-stroke ``angle_from -> angle_to`` in ``duration`` s.

    Args:
        angle_from, angle_to, duration: The half-stroke actually swept [rad, rad, s].
        power: Whether it is a power stroke (it then ends at ``bias + amplitude``).
        bias, amplitude, period, ratio: The latched pattern (eq. 21).
        drag_constant, inertia_constant: ``k`` [N s^2] and ``m_p S_p / 2`` [kg m] (eqs. 13, 15).
        fast: The fast step's ``J1``, ``sin`` and ``cos`` (:mod:`pectoral_gym.model.fast_step`).

    Returns:
        ``G``; 1 for the pattern's own half-stroke and for a pattern without amplitude (no phasor).
    """
    low, high = bias - amplitude, bias + amplitude
    start = low if power else high
    if amplitude <= 0.0 or angle_from == start or duration <= 0.0:
        return 1.0
    t_power = period / (ratio + 1.0)  # eq. (21)
    t_recovery = period - t_power
    if fast:  # the two half-strokes' means share J1 and sin: k pi^2 gA J1(gA) sin(g0) (1/d1 - 1/d2) / T
        f_power, _ = half_stroke_mean_force(low, high, t_power, drag_constant, fast)
        mean = f_power * t_power * (1.0 - t_power / t_recovery) / period
    else:
        f_power, _ = half_stroke_mean_force(low, high, t_power, drag_constant, fast)
        f_recovery, _ = half_stroke_mean_force(high, low, t_recovery, drag_constant, fast)
        mean = (f_power * t_power + f_recovery * t_recovery) / period
    if power:
        regular = half_stroke_ripple_square(low, high, t_power, drag_constant, inertia_constant, mean, fast)
    else:
        regular = half_stroke_ripple_square(high, low, t_recovery, drag_constant, inertia_constant, mean, fast)
    if regular <= 0.0:
        return 1.0
    swept = half_stroke_ripple_square(angle_from, angle_to, duration, drag_constant, inertia_constant, mean, fast)
    return math.sqrt(math.sqrt(swept / regular))
