"""Seeded radio conditions between the PC and the robot: delay, jitter, loss, fades (one model, two carriers).

:class:`RadioChannel` decides, frame by frame, whether an XBee frame is lost and how long it takes:

* ``latency`` ``(lo, hi)``: each frame is delayed by a uniform draw from ``[lo, hi]`` (one-way). By
  default frames of one direction keep their order (a serial radio: a late frame holds up the ones
  behind it); ``reorder=True`` lets a later frame overtake a slower one.
* ``loss``: each frame is lost independently with this probability.
* ``burst`` ``(fraction, length)``: fades of ``length`` seconds cover ``fraction`` of the time (gaps
  between fades exponential with mean ``length (1 - fraction) / fraction``); every frame that would be
  *sent* during a fade is lost, in both directions.

All times are robot seconds. Every draw comes from one generator seeded with ``seed``. The carriers are
:class:`pectoral_gym.hardware.radio.radioproxy.RadioProxy` (TCP, wall clock) and
:class:`pectoral_gym.hardware.radio.pipe.StreamPair` (in-process, on a :mod:`pectoral_gym.hardware.clock`
clock, where the whole run is deterministic for a seed).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pectoral_gym.hardware.radio.xbee import START

__all__ = ["ProxyStats", "RadioChannel", "pair"]


@dataclass
class ProxyStats:
    """Frames through a channel (cumulative); ``up`` is PC -> robot, ``down`` robot -> PC.

    Attributes:
        up_sent: Frames delivered to the robot.
        up_lost: Frames to the robot lost (at random or in a fade).
        down_sent: Frames delivered to the PC.
        down_lost: Frames to the PC lost.
        fades: Fades begun so far.
    """

    up_sent: int = 0
    up_lost: int = 0
    down_sent: int = 0
    down_lost: int = 0
    fades: int = 0


def pair(value: float | tuple[float, float], name: str) -> tuple[float, float]:
    """``(lo, hi)`` seconds from a number or a pair, checked ``0 <= lo <= hi < inf``."""
    lo, hi = (value, value) if isinstance(value, (int, float)) else (float(value[0]), float(value[1]))
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo <= hi):
        raise ValueError(f"{name} must be s or (lo, hi) s with 0 <= lo <= hi, got {value!r}")
    return float(lo), float(hi)


class RadioChannel:
    """The radio conditions of the module docstring, frame by frame.

    Args:
        latency: One-way delay per frame [robot s]: a number, or ``(lo, hi)`` for a uniform draw.
        loss: Probability that a frame is lost, each direction, independently, in ``[0, 1)``.
        burst: ``(fraction, length)``: fades of ``length`` robot seconds covering ``fraction`` of the time
            (``fraction`` in ``[0, 1)``); ``None`` for no fades.
        seed: Seed of every draw (losses, delays, fades).
        reorder: Let a faster frame overtake a slower one of the same direction.

    Attributes:
        stats: A :class:`ProxyStats`.
        log: ``None``, or a list to which every frame appends ``(stamp, "up"/"down", lost)`` (the stamp the
            carrier passes to :meth:`route`).
        drop_if: ``None``, or ``f(direction, raw_frame) -> bool``: frames it returns True for are lost too
            (a scripted loss, for deterministic reproductions).
    """

    def __init__(self, latency: float | tuple[float, float] = 0.0, loss: float = 0.0,
                 burst: tuple[float, float] | None = None, seed: int | None = None, reorder: bool = False):
        self.latency = pair(latency, "latency")
        if not 0.0 <= loss < 1.0:
            raise ValueError(f"loss must be in [0, 1), got {loss!r}")
        if burst is not None and not (0.0 <= burst[0] < 1.0 and math.isfinite(burst[1]) and burst[1] > 0):
            raise ValueError(f"burst must be (fraction in [0, 1), length > 0 s), got {burst!r}")
        self.loss, self.burst, self.reorder = float(loss), burst, bool(reorder)
        self.stats = ProxyStats()
        self.log: list[tuple[float, str, bool]] | None = None
        self.drop_if: Callable[[str, bytes], bool] | None = None
        self._rng = np.random.default_rng(seed)
        self._fade = (math.inf, math.inf)  # (start, end) of the current or next fade [robot s]
        if burst is not None and burst[0] > 0:
            self._fade = self._next_fade(0.0)

    @property
    def clean(self) -> bool:
        """Whether the channel neither delays nor loses anything (``drop_if`` aside)."""
        return self.latency == (0.0, 0.0) and self.loss == 0.0 and self._fade[0] == math.inf

    def _next_fade(self, after: float) -> tuple[float, float]:
        fraction, length = self.burst
        start = after + float(self._rng.exponential(length * (1.0 - fraction) / fraction))
        return start, start + length

    def _in_fade(self, t: float) -> bool:
        """Whether robot time ``t`` (non-decreasing between calls) falls in a fade."""
        while t >= self._fade[1]:
            self._fade = self._next_fade(self._fade[1])
            self.stats.fades += 1
        return self._fade[0] <= t

    def route(self, unit: bytes, direction: str, t: float, stamp: float | None = None) -> float | None:
        """The delay [robot s] of ``unit`` sent at robot time ``t`` towards ``direction`` (``"up"``/``"down"``).

        ``None`` if it is lost. Only whole frames (starting with the XBee delimiter) can be lost; other
        bytes are delayed alike. ``stamp`` (default ``t``) goes into :attr:`log`.
        """
        is_frame = unit[:1] == bytes((START,))
        lost = is_frame and (self._in_fade(t) or (self.loss > 0 and self._rng.random() < self.loss))
        if is_frame and not lost and self.drop_if is not None:
            lost = bool(self.drop_if(direction, unit))
        delay = float(self._rng.uniform(*self.latency))
        if self.log is not None and is_frame:
            self.log.append((t if stamp is None else stamp, direction, bool(lost)))
        if is_frame:
            name = f"{direction}_{'lost' if lost else 'sent'}"
            setattr(self.stats, name, getattr(self.stats, name) + 1)
        return None if lost else delay
