"""The robot firmware's command path for a batch of model fish: what the robot's fins latch, and when.

On the robot a command does not reach the fins as sent (:mod:`pectoral_gym.hardware.radio.firmware`): the
firmware clips it to the servo limits (``clip_beats``), slews its setpoint towards it by at most ``max_rate``
per second and parameter every tick (``rate_limit``; bias and amplitude 180 deg/s), and hands the setpoint to
the fins, which latch it at their next stroke turning point with the transitional half-stroke bounded by the
servos' peak rate (``stretch_transition``; :func:`pectoral_gym.hardware.finreplay.advance_with_firmware`). A
fin that reaches a turning point while the setpoint is still on its way latches the pattern half-way. The
backup shield's on-the-spot spin (:data:`pectoral_gym.agents.controllers.turning.SPIN_CYCLE`) changes the
biases by up to 37 deg every control period, 0.2 s of slewing, and its turn is made of transitional strokes
(docs/model.md 3.7): the half-way latches change them. From swimming at 20 deg, then 10 s of the spin, the full
model drifts at 0.015-0.017 m/s when the patterns latch as sent, and at 0.039-0.042 m/s through the firmware's
rules (``PectoralFish`` full model, the spin from each of its four phases); the planning model through the same
rules drifts alike (``tests/test_firmware_path.py``).

:class:`FirmwarePath` runs those rules for ``n`` fish of any model with the fins' stroke layout
(:mod:`pectoral_gym.model.strokes`), ticking at the firmware's tick while a setpoint moves or a transition is
stretched, and in one step otherwise.
"""

from __future__ import annotations

import numpy as np

from pectoral_gym.hardware.finreplay import CHUNK
from pectoral_gym.hardware.radio.firmware import ServoLimits, clip_beats, rate_limit, rest_beats, stretch_transition
from pectoral_gym.model import strokes
from pectoral_gym.model.models import FishModel

__all__ = ["FirmwarePath"]


def _clip(beats: np.ndarray, limits: ServoLimits) -> np.ndarray:
    """The firmware's ``clip_beats`` of patterns ``(..., 2, 4)`` (its one definition, batched)."""
    return clip_beats(beats, limits)[0]


class FirmwarePath:
    """The firmware's setpoints of ``n`` fish and the rules that bring a command to their fins.

    Args:
        n: Number of fish.
        limits: The servo limits (the firmware's default :class:`ServoLimits`).
        tick: The firmware's tick [s] (the emulator's and the PC's fin replay's).

    Attributes:
        setpoint: ``(n, 2, 4)`` the slewed patterns the fins are handed (bias, amplitude, period, ratio; right first).
        target: ``(n, 2, 4)`` the clipped commands the setpoints slew towards.
    """

    def __init__(self, n: int, limits: ServoLimits | None = None, tick: float = CHUNK):
        self.limits = limits or ServoLimits()
        self.tick = float(tick)
        self.setpoint = np.empty((int(n), 2, 4))
        self.target = np.empty((int(n), 2, 4))
        self.reset()

    def reset(self) -> None:
        """Power-up or a halt: the setpoints are the firmware's rest (90 deg, no amplitude) and so are the targets."""
        self.setpoint[:] = rest_beats()
        self.target[:] = self.setpoint

    def copy_from(self, other: FirmwarePath, index: int = 0) -> None:
        """Every fish's setpoint and target from fish ``index`` of ``other``."""
        self.setpoint[:] = other.setpoint[index]
        self.target[:] = other.target[index]

    def command(self, beats: np.ndarray) -> None:
        """A new command ``(n, 2, 4)`` arrives: the setpoints slew towards it clipped to the servo limits."""
        self.target[:] = _clip(beats, self.limits)

    def _slew(self, h: float) -> None:
        """The firmware's tick of ``h`` [s]: ``rate_limit``, then ``clip_beats``.

        A setpoint within one step of its target lands on it exactly, so that a settled batch is recognised by equality.
        """
        step = np.asarray(self.limits.max_rate, dtype=np.float64) * h
        near = np.abs(self.target - self.setpoint) <= step
        slewed = _clip(rate_limit(self.setpoint, self.target, h, self.limits), self.limits)
        self.setpoint[:] = np.where(near, self.target, slewed)

    def _hand_over(self, model: FishModel) -> bool:
        """Command the fins the (stretched) setpoints; whether they are settled (nothing changes until the target).

        Settled: every setpoint is at its target and no transition needs stretching at the fins' next turning point.
        """
        fins = model.fins
        still = fins[..., strokes.ANGLE_FROM] == fins[..., strokes.ANGLE_TO]
        next_power = still | (fins[..., strokes.POWER] < 0.5)
        safe = stretch_transition(self.setpoint, fins[..., strokes.ANGLE_TO], next_power, self.limits)
        model.command_array(safe, validate=False)
        return bool(np.array_equal(self.setpoint, self.target) and np.array_equal(safe, self.setpoint))

    def advance(self, model: FishModel, duration: float) -> np.ndarray:
        """Advance ``model`` (``n`` fish) by ``duration`` [s] under the firmware's rules; returns its state.

        Ticks as :func:`pectoral_gym.hardware.finreplay.advance_with_firmware` does (slew, then hand over, then
        advance one tick) while anything is on its way, then the rest in one step.
        """
        left = float(duration)
        while left > 1e-12:
            h = min(self.tick, left)
            self._slew(h)
            if self._hand_over(model):
                model.advance(left)
                break
            model.advance(h)
            left -= h
        return model.state
