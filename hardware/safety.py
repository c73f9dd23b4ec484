"""PC-side safety rules of the hardware environment (the robot enforces its own in :mod:`hardware.firmware`).

* :func:`check_action`: a non-finite action is rejected before anything is sent.
* :class:`CommandFilter`: commands clipped to the servo limits and rate-limited per control step.
* :func:`in_geofence`: the fish's nose or tail within ``margin`` of a tank wall -> stop, end the episode.
* :class:`TrackingWatch`: tracking lost for longer than ``timeout`` -> stop, end the episode.
* :func:`install_stop_handlers`: Ctrl-C and SIGTERM send stop before the program ends.
"""

from __future__ import annotations

import math
import signal
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hardware.firmware import ServoLimits, clip_beats, rate_limit
from pectoral_gym.params import TANK_LENGTH, TANK_WIDTH

__all__ = ["SafetyConfig", "check_action", "CommandFilter", "in_geofence", "TrackingWatch",
           "install_stop_handlers"]


@dataclass(frozen=True)
class SafetyConfig:
    """PC-side safety settings.

    Attributes:
        limits: Servo limits (clipping and rate limiting), shared with the firmware rules.
        geofence_margin: Stop when the nose or tail comes this close to a wall [m].
        tracking_timeout: Stop when the fish has not been seen for this long [s].
        link_timeout: Stop when the robot has not answered for this long [s].
    """

    limits: ServoLimits = field(default_factory=ServoLimits)
    geofence_margin: float = 0.05
    tracking_timeout: float = 0.5
    link_timeout: float = 1.0

    def __post_init__(self) -> None:
        for name in ("geofence_margin", "tracking_timeout", "link_timeout"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"SafetyConfig.{name} must be a finite number >= 0, got {value!r}")


def check_action(action, size: int = 8) -> np.ndarray:
    """``action`` as a float64 array of ``size``; ``ValueError`` if it has another shape or is not finite."""
    try:
        arr = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"action must be {size} numbers, got {action!r}") from None
    if arr.shape != (size,):
        raise ValueError(f"action must have shape ({size},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"action must be finite, got {arr.tolist()}; nothing was sent to the robot")
    return arr


class CommandFilter:
    """Clip fin commands ``(2, 4)`` to the servo limits and rate-limit them between successive calls.

    Args:
        limits: Servo limits.

    Attributes:
        last: The last command let through (``None`` before the first).
        clipped, rate_limited: Whether the last call changed the command for either reason.
    """

    def __init__(self, limits: ServoLimits):
        self.limits = limits
        self.last: np.ndarray | None = None
        self.clipped = self.rate_limited = False

    def reset(self, beats: np.ndarray | None = None) -> None:
        """Forget the history (the next command is only clipped), or start from ``beats``."""
        self.last = None if beats is None else np.asarray(beats, dtype=float).reshape(2, 4).copy()

    def __call__(self, beats: np.ndarray, dt: float) -> np.ndarray:
        """The command to send for ``beats`` after ``dt`` seconds since the previous one."""
        clipped, self.clipped = clip_beats(beats, self.limits)
        out = clipped if self.last is None else rate_limit(self.last, clipped, dt, self.limits)
        out = clip_beats(out, self.limits)[0]
        self.rate_limited = bool(np.any(np.abs(out - clipped) > 1e-12))
        self.last = out
        return out.copy()


def in_geofence(x: float, y: float, psi: float, body_length: float, margin: float) -> bool:
    """Whether the nose or the tail (``X +- L/2 cos psi``, ``Y +- L/2 sin psi``) is within ``margin`` of a wall.

    A non-finite pose counts as outside (stop rather than guess).
    """
    if not all(math.isfinite(v) for v in (x, y, psi)):
        return True
    half = 0.5 * body_length
    for sign in (1.0, -1.0):
        px, py = x + sign * half * math.cos(psi), y + sign * half * math.sin(psi)
        if not (margin <= px <= TANK_LENGTH - margin and margin <= py <= TANK_WIDTH - margin):
            return True
    return False


class TrackingWatch:
    """How long the fish has gone unseen.

    Args:
        timeout: Lost longer than this [s] -> :meth:`expired`.
    """

    def __init__(self, timeout: float):
        self.timeout = float(timeout)
        self.last_seen: float | None = None
        self.reason = ""

    def reset(self, now: float) -> None:
        """Start watching at ``now`` as if the fish had just been seen."""
        self.last_seen, self.reason = now, ""

    def update(self, now: float, ok: bool, reason: str = "") -> None:
        """Record a tracking result at ``now``: seen (``ok``) or not (``reason``)."""
        if ok:
            self.last_seen, self.reason = now, ""
        elif reason:
            self.reason = reason

    def lost_for(self, now: float) -> float:
        """Seconds since the fish was last seen."""
        return math.inf if self.last_seen is None else max(0.0, now - self.last_seen)

    def expired(self, now: float) -> bool:
        """Whether the fish has been lost for longer than ``timeout``."""
        return self.lost_for(now) > self.timeout


def install_stop_handlers(stop: Callable[[], object]) -> Callable[[], None]:
    """Make SIGINT (Ctrl-C) and SIGTERM call ``stop()`` before the usual ending; returns a function that undoes it.

    SIGINT then raises ``KeyboardInterrupt`` and SIGTERM ``SystemExit(143)``, so ``finally`` blocks
    and ``close()`` still run. Outside the main thread nothing is installed (Python allows signal
    handlers only there).
    """
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}

    def handler(signum, frame):
        try:
            stop()
        finally:
            if signum == signal.SIGINT:
                raise KeyboardInterrupt
            raise SystemExit(128 + signum)

    for sig in previous:
        signal.signal(sig, handler)

    def restore() -> None:
        for sig, old in previous.items():
            signal.signal(sig, old)

    return restore
