"""CasADi expressions of the averaged model's corrections of a half-stroke, for optimal control (NMPC).

The averaged model's transitional-stroke forcing (``docs/model.md`` section 3.7) is here as
its exact building blocks, :func:`half_stroke_mean_force_sx`, :func:`power_stroke_excess_sx` and
:func:`transition_forcing_sx` (parity with the compiled kernel, ``stroke_corrections._transition``, in
``tests/test_symbolic.py``). Which half-stroke is transitional depends on the fins' stroke phase,
a discrete state; the NMPC baseline, which does not observe it, uses their expectation over the
phase (:func:`expected_transition_impulse_sx`, ``pectoral_gym.agents.nmpc.problem``). The beat-mean
ripple offset of a pattern (section 3.8) is :func:`ripple_offset_sx`.

Like :mod:`pectoral_gym.model.symbolic`, whose Bessel series they use, every function accepts
CasADi ``SX``/``MX`` (or plain numbers) and returns expressions of the same kind; CasADi is an
optional dependency (``pip install pectoral-gym[nmpc]``).
"""

from __future__ import annotations

import math

try:
    import casadi as ca
except ImportError as err:  # pragma: no cover - exercised only without the nmpc extra
    raise ImportError(
        "pectoral_gym.model.symbolic_corrections needs CasADi: pip install 'pectoral-gym[nmpc]' (or pip install casadi)"
    ) from err

from pectoral_gym.model.averaging import ODD_MOMENT_SERIES
from pectoral_gym.model.params import FishParams
from pectoral_gym.model.symbolic import bessel_j1_sx

__all__ = ["expected_transition_impulse_sx", "half_stroke_mean_force_sx", "power_stroke_excess_sx",
           "ripple_offset_sx", "transition_forcing_sx"]


def half_stroke_mean_force_sx(angle_from, angle_to, duration, drag_constant: float):
    """Exact mean ``(f_hx, f_hy)`` [N] of one half-cosine half-stroke of the right fin (``docs/model.md`` 3.7).

    As :func:`pectoral_gym.model.averaging.half_stroke_mean_force`:
    ``k pi^2 |half| J1(half) (sin mid, cos mid) / d^2``.
    """
    half = 0.5 * (angle_to - angle_from)
    mid = 0.5 * (angle_to + angle_from)
    base = drag_constant * math.pi**2 * ca.fabs(half) * bessel_j1_sx(half) / (duration * duration)
    return ca.vertcat(base * ca.sin(mid), base * ca.cos(mid))


def power_stroke_excess_sx(beat, drag_constant: float):
    """Impulse ``(X_fx, X_fy)`` [N s] of a regular power stroke beyond the cycle mean (right fin, K = 1).

    As :func:`pectoral_gym.model.averaging.power_stroke_excess`: ``X = d1 (mean_power - mean_cycle)``.
    """
    bias, amplitude, period, ratio = beat[0], beat[1], beat[2], beat[3]
    d1 = period / (ratio + 1.0)
    d2 = ratio * d1
    power = half_stroke_mean_force_sx(bias - amplitude, bias + amplitude, d1, drag_constant)
    recovery = half_stroke_mean_force_sx(bias + amplitude, bias - amplitude, d2, drag_constant)
    return d1 * power - d1 * (d1 * power + d2 * recovery) / period


def transition_forcing_sx(angle_from, beat, previous_power, power: bool, side: float, params: FishParams):
    """Forcing ``(f_x, f_y, tau)`` of one half-stroke of ``beat`` beyond its regular one (``docs/model.md`` 3.7).

    The two terms of ``stroke_corrections._transition``: the exact mean of the half-stroke swept from
    ``angle_from`` minus that of the regular half-stroke (same end and duration); on a recovery
    stroke, plus ``(X(previous_power) - X(beat)) / d2`` for the pattern of the power stroke before.

    Args:
        angle_from: Fin angle [rad] where the half-stroke starts (the previous turning point).
        beat: The latched pattern ``(bias, amplitude, period, ratio)``.
        previous_power: Pattern of the fin's last power stroke (used when ``power`` is False).
        power: True for a power stroke (to ``bias + amplitude``), False for a recovery stroke.
        side: +1 right fin, -1 left fin (eq. 18 mirrored).
        params: Model parameters.
    """
    bias, amplitude, period, ratio = beat[0], beat[1], beat[2], beat[3]
    k = params.fin_drag_constant
    d1 = period / (ratio + 1.0)
    if power:
        duration, regular_start, angle_to = d1, bias - amplitude, bias + amplitude
    else:
        duration, regular_start, angle_to = ratio * d1, bias + amplitude, bias - amplitude
    delta = (half_stroke_mean_force_sx(angle_from, angle_to, duration, k)
             - half_stroke_mean_force_sx(regular_start, angle_to, duration, k))
    if not power:
        delta = delta + (power_stroke_excess_sx(previous_power, k) - power_stroke_excess_sx(beat, k)) / duration
    return ca.vertcat(delta[0], side * delta[1], side * params.fin_offset * delta[0])


def ripple_offset_sx(beat, side: float, params: FishParams):
    """Beat-mean impulse offset ``(M_x, M_y, M_tau)`` of one fin's pattern (``docs/model.md`` 3.8).

    As :func:`pectoral_gym.model.averaging.ripple_offset` (the same closed form and series), with the
    left fin's sway and moment mirrored (``side = -1``). The averaged model adds its change,
    spread over the half-stroke, where a fin starts, changes or parks a pattern.
    """
    bias, amplitude, period, ratio = beat[0], beat[1], beat[2], beat[3]
    k = params.fin_drag_constant
    h2 = amplitude * amplitude
    term, odd = amplitude, 0.0
    for n, coefficient in enumerate(ODD_MOMENT_SERIES):
        odd = odd + coefficient * term
        term = term * (-h2) / ((2 * n + 2) * (2 * n + 3))
    a = k * math.pi**2 * amplitude * bessel_j1_sx(amplitude) * (ratio + 1.0 / ratio) / (2.0 * period)
    b = 2.0 * k * h2 * odd / period
    mx = a * ca.sin(bias) + b * ca.cos(bias)
    my = a * ca.cos(bias) - b * ca.sin(bias)
    return ca.vertcat(mx, side * my, side * params.fin_offset * mx)


def expected_transition_impulse_sx(previous, beat, side: float, params: FishParams):
    """Expected impulse ``(f_x, f_y, tau) dt`` [N s, N m s] of the switch from pattern ``previous`` to ``beat``.

    For patterns with the same period and ratio, commanded at an unknown stroke phase (uniform over
    the beat): with probability ``zeta / (zeta + 1)`` the fin is in a recovery stroke of ``previous``
    and the next, transitional, stroke is ``beat``'s power stroke from ``previous``'s lower turning
    point; otherwise it is in a power stroke and the next is ``beat``'s recovery from the upper one,
    which also returns ``previous``'s power-stroke excess. Each stroke's impulse is its
    :func:`transition_forcing_sx` times its duration. Zero when ``beat`` equals ``previous``.
    """
    bias0, amplitude0 = previous[0], previous[1]
    period, ratio = beat[2], beat[3]
    d1 = period / (ratio + 1.0)
    d2 = ratio * d1
    into_power = transition_forcing_sx(bias0 - amplitude0, beat, previous, True, side, params) * d1
    into_recovery = transition_forcing_sx(bias0 + amplitude0, beat, previous, False, side, params) * d2
    return (ratio * into_power + into_recovery) / (ratio + 1.0)
