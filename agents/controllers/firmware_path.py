"""The robot firmware's command path for a batch of model fish: what the robot's fins latch, and when.

On the robot a command does not reach the fins as sent (the fin rules, :mod:`pectoral_gym.model.finrules`): the
firmware clips it to the servo limits (``clip_beats``, :mod:`pectoral_gym.model.servo`) and hands it to the fins,
which latch it at their next stroke turning point, rate-limited there (``slew_at_latch``: a moving fin's pattern
changes by at most ``max_rate`` times the half-stroke that ends; bias and amplitude 180 deg/s) and with the
transitional half-stroke bounded by the servos' peak rate (``stretch_transition``;
:func:`pectoral_gym.model.finrules.advance_with_firmware`). The backup shield's on-the-spot spin
(:data:`pectoral_gym.agents.controllers.turning.SPIN_CYCLE`) changes the biases by up to 37 deg every control
period and its turn is made of transitional strokes (docs/model.md 3.7), which these rules stretch; the
planning model through the same rules drifts as the full model does (``tests/test_firmware_path.py``).

:class:`FirmwarePath` runs those rules for ``n`` fish of any model with the fins' stroke layout
(:mod:`pectoral_gym.model.strokes`), ticking at the firmware's tick while a latch would change what the fins run
or a transition is stretched, and in one step otherwise.
"""

from __future__ import annotations

import numpy as np

from pectoral_gym.model.finrules import CHUNK, next_latch
from pectoral_gym.model.models import FishModel
from pectoral_gym.model.servo import ServoLimits, clip_beats, rest_beats

__all__ = ["FirmwarePath"]


def _clip(beats: np.ndarray, limits: ServoLimits) -> np.ndarray:
    """The firmware's ``clip_beats`` of patterns ``(..., 2, 4)`` (its one definition, batched)."""
    return clip_beats(beats, limits)[0]


class FirmwarePath:
    """The firmware's commands to ``n`` fish and the rules that bring them to their fins.

    Args:
        n: Number of fish.
        limits: The servo limits (the firmware's default :class:`ServoLimits`).
        tick: The firmware's tick [s] (the emulator's and the PC's fin replay's).

    Attributes:
        target: ``(n, 2, 4)`` the clipped commands (bias, amplitude, period, ratio; right first).
    """

    def __init__(self, n: int, limits: ServoLimits | None = None, tick: float = CHUNK):
        self.limits = limits or ServoLimits()
        self.tick = float(tick)
        self.target = np.empty((int(n), 2, 4))
        self.reset()

    def reset(self) -> None:
        """Power-up or a halt: the targets are the firmware's rest (90 deg, no amplitude)."""
        self.target[:] = rest_beats()

    def copy_from(self, other: FirmwarePath, index: int = 0) -> None:
        """Every fish's target from fish ``index`` of ``other``."""
        self.target[:] = other.target[index]

    def command(self, beats: np.ndarray) -> None:
        """A new command ``(n, 2, 4)`` arrives, clipped to the servo limits."""
        self.target[:] = _clip(beats, self.limits)

    def _hand_over(self, model: FishModel) -> bool:
        """Command the fins what their next turning point latches; whether they are settled.

        Settled (nothing changes until the next command): what the fins latch next is the target itself
        (``slew_at_latch`` and ``stretch_transition`` leave it as it is).
        """
        safe = next_latch(self.target, model.fins, self.limits)
        model.command_array(safe, validate=False)
        return bool(np.array_equal(safe, self.target))

    def advance(self, model: FishModel, duration: float) -> np.ndarray:
        """Advance ``model`` (``n`` fish) by ``duration`` [s] under the firmware's rules; returns its state.

        Ticks as :func:`pectoral_gym.model.finrules.advance_with_firmware` does (hand over, then advance one
        tick) while anything is on its way, then the rest in one step.
        """
        left = float(duration)
        while left > 1e-12:
            h = min(self.tick, left)
            if self._hand_over(model):
                model.advance(left)
                break
            model.advance(h)
            left -= h
        return model.state
