"""The fin servos: their limits, written once for the robot's firmware, the PC's rules and the simulated envs.

A fin's half-stroke is a half-cosine (eq. 21, ``docs/model.md`` 3.2): it swings ``2 A`` in ``T_p / (zeta + 1)``
(power) or ``zeta T_p / (zeta + 1)`` (recovery), so its peak rate is ``pi * swing / (2 d)``, and the faster
half-stroke peaks at ``pi A (zeta + 1) / (T_p min(1, zeta))``. A servo that turns at most ``max_speed``
runs a pattern above that rate with its period lengthened to :func:`servo_period`: the firmware's clipping
(:func:`clip_beats`, to all of :class:`ServoLimits`) and the simulated envs' ``servo_limit`` (the peak rate alone)
both call it. What the fins latch of a clipped command, and when, is :mod:`pectoral_gym.model.finrules`'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pectoral_gym.model.jit import njit

__all__ = ["ROBOT_MAX_FIN_RATE", "ServoLimits", "clip_beats", "peak_rates", "rest_beats", "servo_period"]

#: The robot's fin servos: fastest angular rate of a fin [rad/s] (``ServoLimits.max_speed``'s default).
ROBOT_MAX_FIN_RATE = 13.0


@njit(inline="always")
def servo_period(amplitude, period, ratio, max_speed):
    """The beat period [s] a servo turning at most ``max_speed`` [rad/s] runs the pattern with.

    ``max(T_p, pi A (zeta + 1) / (max_speed min(1, zeta)))`` (module docstring): unchanged when both
    half-strokes peak at or below ``max_speed``.

    Args:
        amplitude: ``A`` [rad], >= 0. period: ``T_p`` [s]. ratio: ``zeta`` [-], > 0 (floats or arrays of one
            shape). max_speed: [rad/s], > 0.
    """
    slow = math.pi * amplitude * (ratio + 1.0) / (max_speed * np.fmin(1.0, ratio))
    return np.fmax(period, slow)


def _default_rate() -> tuple[float, float, float, float]:
    return (math.radians(180.0), math.radians(180.0), 4.0, 10.0)


@dataclass(frozen=True)
class ServoLimits:
    """What the fin servos can do; commands are clipped to these (PC side and robot side alike).

    The one home of the servo limits: the robot's firmware, the PC's safety rules, the fin replay, the backup
    shield's predictions and the calibration all take theirs from here.

    The defaults admit the simulated environments' default action ranges except their fastest strokes:
    a power stroke peaks at ``pi A (zeta + 1) / T_p`` (eq. 21), above ``max_speed`` for large amplitudes
    at short periods and high ratios, e.g. 19.7 rad/s for (90 deg, 30 deg, 0.5 s, 5), which
    :func:`clip_beats` slows to a 0.76 s period.

    Attributes:
        angle_min: Smallest fin angle [rad] (stroke ``bias - amplitude``).
        angle_max: Largest fin angle [rad] (stroke ``bias + amplitude``).
        period_min: Shortest fin-beat period [s].
        period_max: Longest fin-beat period [s].
        ratio_min: Smallest power/recovery speed ratio [-].
        ratio_max: Largest ratio [-].
        max_speed: Fastest fin angular rate [rad/s]: the peak ``|g'|`` of every half-stroke, eq. (21).
        max_rate: Largest change per second of (bias [rad/s], amplitude [rad/s], period [s/s], ratio [1/s]).
    """

    angle_min: float = math.radians(10.0)
    angle_max: float = math.radians(170.0)
    period_min: float = 0.4
    period_max: float = 4.0
    ratio_min: float = 0.5
    ratio_max: float = 6.0
    max_speed: float = ROBOT_MAX_FIN_RATE
    max_rate: tuple[float, float, float, float] = field(default_factory=_default_rate)

    def __post_init__(self) -> None:
        values = (self.angle_min, self.angle_max, self.period_min, self.period_max, self.ratio_min,
                  self.ratio_max, self.max_speed, *self.max_rate)
        if len(self.max_rate) != 4 or not all(math.isfinite(v) for v in values):
            raise ValueError("ServoLimits: all limits must be finite and max_rate must have 4 entries")
        if not 0 <= self.angle_min < self.angle_max <= math.pi:
            raise ValueError(f"ServoLimits: need 0 <= angle_min < angle_max <= pi, got {self.angle_min}, "
                             f"{self.angle_max}")
        if not 0 < self.period_min <= self.period_max or not 0 < self.ratio_min <= self.ratio_max:
            raise ValueError("ServoLimits: need 0 < period_min <= period_max and 0 < ratio_min <= ratio_max")
        if self.max_speed <= 0 or min(self.max_rate) <= 0:
            raise ValueError("ServoLimits: max_speed and max_rate must be > 0")
        # The slowest stroke must be slow enough for the widest swing (stretching always succeeds).
        span = self.angle_max - self.angle_min
        worst = math.pi * span * (self.ratio_min + 1.0) / (2.0 * self.period_max * self.ratio_min)
        worst = max(worst, math.pi * span * (self.ratio_max + 1.0) / (2.0 * self.period_max))
        if worst > self.max_speed:
            raise ValueError(f"ServoLimits: a full swing at period_max peaks at {worst:.2f} rad/s > max_speed; "
                             "raise period_max or narrow the angle or ratio range")


def rest_beats(angles: np.ndarray | None = None) -> np.ndarray:
    """``(2, 4)`` fins held still at ``angles`` (default 90 deg): amplitude 0, period 1 s, ratio 1."""
    angles = np.full(2, math.pi / 2) if angles is None else np.asarray(angles, dtype=float)
    return np.stack([np.array([a, 0.0, 1.0, 1.0]) for a in angles])


def clip_beats(beats: np.ndarray, limits: ServoLimits) -> tuple[np.ndarray, bool]:
    """Clip ``(2, 4)`` fin patterns to ``limits``; returns ``(clipped, changed)``. Input must be finite.

    A batch ``(..., 2, 4)`` is clipped pattern by pattern (``changed``: any of them), as the backup shield's
    rollouts need; 8 values are read as ``(2, 4)``.
    """
    b = _patterns(beats)
    out = b.copy()
    half_range = 0.5 * (limits.angle_max - limits.angle_min)
    out[..., 1] = np.clip(out[..., 1], 0.0, half_range)
    out[..., 0] = np.clip(out[..., 0], limits.angle_min + out[..., 1], limits.angle_max - out[..., 1])
    out[..., 2] = np.clip(out[..., 2], limits.period_min, limits.period_max)
    out[..., 3] = np.clip(out[..., 3], limits.ratio_min, limits.ratio_max)
    # Peak rate of the faster half-stroke, eq. (21): pi A (zeta + 1) / (T_p min(1, zeta)); slow the period.
    out[..., 2] = servo_period(out[..., 1], out[..., 2], out[..., 3], limits.max_speed)  # <= period_max (ServoLimits)
    return out, bool(np.any(np.abs(out - b) > 1e-12))


def _patterns(beats: np.ndarray) -> np.ndarray:
    """A float copy of ``beats`` as ``(..., 2, 4)`` patterns (8 values as one ``(2, 4)``)."""
    b = np.array(beats, dtype=float)
    return b if b.shape[-2:] == (2, 4) else b.reshape(2, 4)


def peak_rates(beats: np.ndarray) -> np.ndarray:
    """``(2, 2)`` peak ``|g'|`` [rad/s] of the power and recovery half-strokes of ``(2, 4)`` patterns.

    Each half of eq. (21) is a half-cosine: swing ``2 A`` in ``T_p / (zeta + 1)`` (power) or
    ``zeta T_p / (zeta + 1)`` (recovery); the peak of ``half * pi / d * sin`` is ``pi * swing / (2 d)``.
    """
    b = np.asarray(beats, dtype=float).reshape(2, 4)
    a, period, ratio = b[:, 1], b[:, 2], b[:, 3]
    power = math.pi * a * (ratio + 1.0) / period
    return np.stack([power, power / ratio], axis=1)
