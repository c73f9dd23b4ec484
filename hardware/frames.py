"""Frames and the frame-source protocol shared by every camera in ``hardware/``.

Timestamps are seconds on the ``time.monotonic()`` clock of this machine (on Linux the same clock in every
process, so a frame served by an emulator process on the same host keeps its capture time).
"""

from __future__ import annotations

import threading
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np

__all__ = ["CameraLostError", "Frame", "FrameSource", "NewestSlot"]


class Frame(NamedTuple):
    """One camera image.

    Attributes:
        image: (H, W, 3) uint8 BGR image.
        timestamp: Capture time [s] on the ``time.monotonic()`` clock.
    """

    image: np.ndarray
    timestamp: float


@runtime_checkable
class FrameSource(Protocol):
    """Anything that yields timestamped frames."""

    def read(self) -> Frame | None:
        """Return the newest frame not returned before, or ``None`` if there is none or the source is lost."""
        ...

    def close(self) -> None:
        """Release the device, file or connection (safe to call twice)."""
        ...


class CameraLostError(RuntimeError):
    """A camera could not be opened."""


class NewestSlot:
    """A one-item mailbox between a grabber thread and ``read()``: newest item only, each taken at most once."""

    def __init__(self) -> None:
        self._condition = threading.Condition()
        self._item: Frame | None = None
        self._sequence = 0
        self._taken = 0

    def put(self, item: Frame) -> None:
        """Replace the item (an untaken older one is dropped) and wake a waiting consumer."""
        with self._condition:
            self._item = item
            self._sequence += 1
            self._condition.notify_all()

    def take(self, timeout: float) -> Frame | None:
        """The item if it was not taken before, waiting up to ``timeout`` seconds for one; else ``None``."""
        with self._condition:
            if self._sequence == self._taken and timeout > 0:
                self._condition.wait_for(lambda: self._sequence != self._taken, timeout)
            if self._sequence == self._taken:
                return None
            self._taken = self._sequence
            return self._item

    def wake(self) -> None:
        """Wake a waiting consumer without an item (the producer stopped)."""
        with self._condition:
            self._condition.notify_all()
