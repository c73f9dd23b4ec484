"""Frames and the frame-source protocol shared by every camera in ``hardware/``.

Timestamps are seconds on the clock of the stack (:mod:`pectoral_gym.hardware.clock`): by default
``time.monotonic()`` of this machine (on Linux the same clock in every process, so a frame served by an
emulator process on the same host keeps its capture time); a lockstep emulation's virtual clock.
"""

from __future__ import annotations

import collections
import math
import threading
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np

from pectoral_gym.hardware.clock import REAL_CLOCK, Clock

__all__ = ["CameraLostError", "Frame", "FrameGrabber", "FrameSource", "NewestSlot"]


class Frame(NamedTuple):
    """One camera image.

    Attributes:
        image: (H, W, 3) uint8 BGR image.
        timestamp: Capture time [s] on the stack's clock (``time.monotonic()`` for real time).
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
    """A one-item mailbox between a grabber thread and ``read()``: newest item only, each taken at most once.

    Args:
        clock: The clock ``take``'s timeout counts on.
    """

    def __init__(self, clock: Clock = REAL_CLOCK) -> None:
        self._condition = clock.condition()
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


class FrameGrabber:
    """Reads any :class:`FrameSource` in a thread of its own; :meth:`read` hands out the newest frame at once.

    Whatever the source does (renders for tens of milliseconds, blocks in ``read()`` for ever, raises),
    the caller of :meth:`read` never waits: it gets the newest frame not returned before, or ``None``.
    Frames keep the stamps their source gave them at capture. A source that blocks, raises or goes
    quiet shows up as no new frames, with :attr:`lost_reason` saying why. The grabber owns the source:
    :meth:`close` closes it.

    Args:
        source: The frame source; only the grabber's thread calls its ``read()``.
        max_rate: Most ``read()`` calls per wall second after a frame (a source that renders on demand,
            such as the emulated camera, renders at this rate); a source that returns ``None`` is polled
            again after a quarter of that period [1/s].
        stale_after: No frame for this long, or one ``read()`` of the source taking this long, makes
            :attr:`lost_reason` non-empty [s].
        name: Name of the thread.
        clock: The clock of every time, wait and the thread (:mod:`pectoral_gym.hardware.clock`).

    Attributes:
        frames: Frames received from the source.
        error: ``"Type: message"`` of the last exception the source raised, ``""`` once a frame arrives.
        ages: Wall time from each recent frame's capture stamp to the moment it became available [s]
            (for frames stamped on ``clock``; the newest 512).
    """

    def __init__(self, source: FrameSource, max_rate: float = 30.0, stale_after: float = 1.0,
                 name: str = "frame-grabber", clock: Clock = REAL_CLOCK) -> None:
        if not (math.isfinite(max_rate) and max_rate > 0):
            raise ValueError(f"max_rate must be a finite number > 0 [1/s], got {max_rate!r}")
        if not (math.isfinite(stale_after) and stale_after > 0):
            raise ValueError(f"stale_after must be a finite number > 0 [s], got {stale_after!r}")
        if not callable(getattr(source, "read", None)):
            raise TypeError(f"source must be a FrameSource (with read() and close()), got {type(source).__name__}")
        self.source = source
        self.period, self.stale_after = 1.0 / float(max_rate), float(stale_after)
        self.frames = 0
        self.error = ""
        self.ages: collections.deque[float] = collections.deque(maxlen=512)
        self.clock = clock
        self._slot = NewestSlot(clock)
        self._last_frame_time = clock.monotonic()
        self._reading_since: float | None = None
        self._stop = clock.event()
        self._thread = clock.thread(self._run, name)
        self._thread.start()

    def _run(self) -> None:
        next_read = self.clock.monotonic()
        while not self._stop.is_set():
            self._reading_since = self.clock.monotonic()
            try:
                frame = self.source.read()
            except Exception as error:  # noqa: BLE001 - any failure of the source is "no frame", with the reason
                frame, self.error = None, f"{type(error).__name__}: {error}"
            finally:
                self._reading_since = None
            now = self.clock.monotonic()
            if frame is None:
                self._stop.wait(self.period / 4)
                continue
            self._last_frame_time, self.frames, self.error = now, self.frames + 1, ""
            try:
                self.ages.append(now - float(frame.timestamp))
            except (TypeError, ValueError):
                pass  # a bad stamp is FrameCheck's to reject
            self._slot.put(frame)
            next_read = max(next_read + self.period, now)
            self._stop.wait(next_read - now)

    def read(self) -> Frame | None:
        """The newest frame not returned before, or ``None``; returns at once."""
        if self._stop.is_set():
            return None
        return self._slot.take(0.0)

    @property
    def lost_reason(self) -> str:
        """Why no frame is coming (``""`` while frames arrive): a blocked or raising source, or silence."""
        now = self.clock.monotonic()
        if self._stop.is_set():
            return "frame grabber closed"
        since = self._reading_since
        if since is not None and now - since > self.stale_after:
            return f"camera read() blocked for {now - since:.2f} s"
        if self.error:
            return f"camera read() raised {self.error}"
        if now - self._last_frame_time > self.stale_after:
            inner = getattr(self.source, "lost_reason", "")
            quiet = f"no frame from the camera for {now - self._last_frame_time:.2f} s"
            return f"{quiet} ({inner})" if inner else quiet
        return ""

    @property
    def lost(self) -> bool:
        """True while :attr:`lost_reason` is non-empty."""
        return bool(self.lost_reason)

    def close(self, timeout: float = 1.0) -> None:
        """Close the source and stop the thread (waiting up to ``timeout`` s for the source's ``read()`` to return).

        Safe to call twice. A thread stuck in the source's ``read()`` is a daemon and is left behind.
        """
        if self._stop.is_set():
            return
        self._stop.set()
        self._slot.wake()
        self.source.close()  # first: closing a source releases a read() blocked in it
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=timeout)
