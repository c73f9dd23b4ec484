"""The fin servos' rate limit, written once for the robot's firmware and the simulated envs.

A fin's half-stroke is a half-cosine (eq. 21, ``docs/model.md`` 3.2): it swings ``2 A`` in ``T_p / (zeta + 1)``
(power) or ``zeta T_p / (zeta + 1)`` (recovery), so its peak rate is ``pi * swing / (2 d)``, and the faster
half-stroke peaks at ``pi A (zeta + 1) / (T_p min(1, zeta))``. A servo that turns at most ``max_speed``
runs a pattern above that rate with its period lengthened to :func:`servo_period` (the firmware's clipping,
``pectoral_gym.hardware.radio.firmware.clip_beats``; the envs' ``servo_limit``).
"""

from __future__ import annotations

import math

import numpy as np

from pectoral_gym.model.jit import njit

__all__ = ["ROBOT_MAX_FIN_RATE", "servo_period"]

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
