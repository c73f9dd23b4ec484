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

from dataclasses import dataclass
from typing import Any

from pectoral_gym.model.params import FishParams
from pectoral_gym.model.tank import Outline, StopRule, coast_rate, outline_circles, stop_need, wall_gaps

__all__ = ["StopBand", "band_violation"]


@dataclass(frozen=True)
class StopBand:
    """The rule and geometry of the stopping-distance band (``pectoral_gym.hardware.safety.geofence.Geofence``'s).

    Attributes:
        rule: The band's :class:`~pectoral_gym.model.tank.StopRule` (margin [m], ``t_r`` [s], ``v_c`` [m/s]).
        k: ``c1 / max(m1, m2)`` [1/m] (:func:`~pectoral_gym.model.tank.coast_rate`).
        outline: The fish's :class:`~pectoral_gym.model.tank.Outline` (half the body length, ``C_p``, ``S_p`` [m]).
    """

    rule: StopRule
    k: float
    outline: Outline

    @classmethod
    def from_params(cls, params: FishParams, rule: StopRule) -> StopBand:
        """The band of a fish with ``params`` under ``rule`` (the supervisor's, or the envs' ``stop_rule``)."""
        if not isinstance(rule, StopRule):
            raise TypeError(f"StopBand needs a pectoral_gym.model.tank.StopRule, got {rule!r}")
        return cls(rule, coast_rate(params), Outline.from_params(params))


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
    needs = []
    for toward in (-vx_w, vx_w, -vy_w, vy_w):  # walls X = 0, X = L, Y = 0, Y = W (tank.wall_gaps' order)
        v = ops.fmax(toward, 0.0)
        needs.append(stop_need(v, band.k, band.rule, ops=ops))
    total = 0.0
    for px, py, r in outline_circles(x, y, c, s, band.outline):  # nose, tail, right and left fin pivot
        for need, gap in zip(needs, wall_gaps(px, py, r), strict=True):
            total = total + ops.fmax(need - gap, 0.0) ** 2
    return total
