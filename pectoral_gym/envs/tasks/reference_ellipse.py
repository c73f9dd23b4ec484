"""The track task's reference point on its ellipse: where it is, and how it moves on (numba, inlined).

The ellipse of env ``i`` is stored in its ``ep`` row (centre ``E_CX, E_CY``, semi-axes ``E_A, E_B``,
direction ``E_DIR`` = +-1 and phase ``E_PHASE``; :mod:`pectoral_gym.envs.layout`); the point sits at
``(cx + a cos phase, cy + b sin phase)`` and moves at a constant speed along the ellipse.
:func:`set_reference` writes its position and velocity to the target entries (``E_TX`` ...);
:func:`move_reference` advances it by one control period. The reset places it
(:func:`pectoral_gym.envs.tasks.episode_start.start_states`), the step moves it
(:func:`pectoral_gym.envs.tasks.kernels.reward_one`).

Units: metres, seconds, radians.
"""

from __future__ import annotations

import math

from pectoral_gym.envs.layout import E_A, E_B, E_CX, E_CY, E_DIR, E_PHASE, E_TVX, E_TVY, E_TX, E_TY
from pectoral_gym.model.jit import njit

__all__ = ["TRACK_SUBSTEPS", "move_reference", "set_reference"]

TRACK_SUBSTEPS = 4  # RK4 steps per control period for the reference point's phase


@njit(inline="always")
def _phase_rate(phase, a, b, direction, speed):
    """d(phase)/dt for a point moving at ``speed`` along the ellipse (a cos phase, b sin phase)."""
    sp, cp = math.sin(phase), math.cos(phase)
    return direction * speed / math.sqrt(a * a * sp * sp + b * b * cp * cp)


@njit(inline="always")
def set_reference(i, ep, speed):
    """Target position and velocity from the ellipse phase of env ``i``."""
    a, b, phase, direction = ep[i, E_A], ep[i, E_B], ep[i, E_PHASE], ep[i, E_DIR]
    sp, cp = math.sin(phase), math.cos(phase)
    ep[i, E_TX] = ep[i, E_CX] + a * cp
    ep[i, E_TY] = ep[i, E_CY] + b * sp
    tx, ty = -a * sp, b * cp  # tangent d/dphase
    norm = math.sqrt(tx * tx + ty * ty)
    ep[i, E_TVX] = direction * speed * tx / norm
    ep[i, E_TVY] = direction * speed * ty / norm


@njit(inline="always")
def move_reference(i, ep, duration, speed):
    """Advance the reference point of env ``i`` by ``duration`` along its ellipse (RK4 on the phase)."""
    a, b, direction = ep[i, E_A], ep[i, E_B], ep[i, E_DIR]
    h = duration / TRACK_SUBSTEPS
    p = ep[i, E_PHASE]
    for _ in range(TRACK_SUBSTEPS):
        k1 = _phase_rate(p, a, b, direction, speed)
        k2 = _phase_rate(p + 0.5 * h * k1, a, b, direction, speed)
        k3 = _phase_rate(p + 0.5 * h * k2, a, b, direction, speed)
        k4 = _phase_rate(p + h * k3, a, b, direction, speed)
        p += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    ep[i, E_PHASE] = (p + math.pi) % (2.0 * math.pi) - math.pi
    set_reference(i, ep, speed)
