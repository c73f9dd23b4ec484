"""The robot env's stopping-distance band as a soft wall term of the NMPC (NumPy and CasADi alike).

On the robot (``pectoral_gym.hardware.env.HardwareFishEnv``) the safety supervisor stops the fish, and ends the
episode, once it could no longer coast to a stop clear of a wall (``pectoral_gym.hardware.safety.geofence.Geofence``):
per wall, the clearance of the fish's outline (a capsule from nose to tail of radius ``C_p`` and a disc of
radius ``S_p`` around each fin pivot ``(0, +-C_p)``) must exceed ``margin + v t_r + ln(max(v, v_c) / v_c) / k``,
``v`` the speed towards that wall, ``t_r`` the reaction time, ``v_c`` the contact speed and
``k = c1 / max(m1, m2)`` (eq. 19 with no fin force along one axis; :func:`pectoral_gym.model.tank.stop_need`).
A planner that keeps only its nose and tail a few centimetres from the walls swims into that band at speed
(about 0.25 m at 0.1 m/s);
:func:`band_violation` prices every circle of the outline against every wall's need instead, so the
plan slows down or turns along a wall in time. The same expression serves the NLP (``ops=casadi``)
and the pricing of rollouts (``ops=numpy``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from pectoral_gym.model.params import FishParams
from pectoral_gym.model.tank import Outline, StopRule, coast_rate, outline_circles, stop_need, wall_gaps

__all__ = ["StopBand", "band_violation"]


@dataclass(frozen=True)
class StopBand:
    """The geometry and rule of the stopping-distance band (``pectoral_gym.hardware.safety.geofence.Geofence``'s).

    Attributes:
        margin: Clearance kept on top of the stopping distance [m].
        reaction_time: ``t_r`` [s].
        contact_speed: ``v_c`` [m/s] (:class:`~pectoral_gym.model.tank.StopRule`).
        k: ``c1 / max(m1, m2)`` [1/m].
        half_length: Half the body length [m] (nose and tail).
        width: ``C_p`` [m]: the capsule's radius and the fin pivots' lateral offset.
        span: ``S_p`` [m]: the radius of the fin discs.
    """

    margin: float
    reaction_time: float
    contact_speed: float
    k: float
    half_length: float
    width: float
    span: float

    @classmethod
    def from_params(cls, params: FishParams, margin: float, reaction_time: float, contact_speed: float) -> StopBand:
        """The band of a fish with ``params`` and the supervisor's ``margin``, reaction time and contact speed."""
        values = (margin, reaction_time, contact_speed)
        if not (all(math.isfinite(v) and v >= 0 for v in values) and contact_speed > 0):
            raise ValueError("stop band margin and reaction time must be finite and >= 0, the contact speed finite "
                             f"and > 0, got {values}")
        return cls(float(margin), float(reaction_time), float(contact_speed), coast_rate(params),
                   *Outline.from_params(params))


def band_violation(x: Any, y: Any, psi: Any, vx: Any, vy: Any, band: StopBand, ops: Any) -> Any:
    """Sum over the outline's circles and the walls of the squared shortfall [m^2] of clearance below the need.

    Args:
        x, y, psi: Pose (tank frame) [m, m, rad].
        vx, vy: Body-frame velocity [m/s] (the state layout of :mod:`pectoral_gym.model.symbolic`).
        band: The band.
        ops: ``numpy`` or ``casadi`` (``cos``, ``sin``, ``log``, ``fmax``).

    Returns:
        Zero exactly when no part of the outline is inside the band (``Geofence.breached`` is false).
    """
    c, s = ops.cos(psi), ops.sin(psi)
    vx_w, vy_w = c * vx - s * vy, s * vx + c * vy
    rule = StopRule(band.margin, band.reaction_time, band.contact_speed)
    needs = []
    for toward in (-vx_w, vx_w, -vy_w, vy_w):  # walls X = 0, X = L, Y = 0, Y = W (tank.wall_gaps' order)
        v = ops.fmax(toward, 0.0)
        needs.append(stop_need(v, band.k, rule, ops=ops))
    total = 0.0
    outline = Outline(band.half_length, band.width, band.span)
    for px, py, r in outline_circles(x, y, c, s, outline):  # nose, tail, right and left fin pivot
        for need, gap in zip(needs, wall_gaps(px, py, r), strict=True):
            total = total + ops.fmax(need - gap, 0.0) ** 2
    return total
