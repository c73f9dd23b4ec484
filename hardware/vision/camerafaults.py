"""A degraded camera for tests: wraps any frame source and makes it drop, freeze, lie about time, lag or block.

:class:`FaultyCamera` reproduces what real cameras and drivers do wrong, one knob per fault; every knob is
an attribute that can be changed while frames flow (a test lets the camera run live, then freezes it):

* ``drop``: each frame is lost with this probability (seeded).
* ``freeze``: ``"repeat"`` (the last live image again and again), ``"cycle"`` (the last ``cycle`` live
  images in turn: a driver handing out its ring of buffers), ``"overlay"`` (the last live image with a
  running clock drawn in its top-left corner, as an IP camera stamps its frames), ``"noisy"`` (the last live
  image with fresh Gaussian noise of ``noise`` grey levels added to every pixel: an analog camera frozen behind
  a capture card, whose noise is added downstream of the frozen image), or ``None`` (live).
  A frozen frame carries the stamp of the source frame it replaces (fresh, increasing, at the source's
  pace), so only its pixels give it away.
* ``clock_offset``: added to every stamp [s] (a camera stamping on a clock ahead or behind).
* ``latency``: each frame is handed out this long after the source delivered it [s].
* ``block``: each ``read()`` blocks this long before reading [s] (``math.inf``: until :meth:`close`).

Pose noise of the emulated camera is :class:`pectoral_gym.hardware.vision.camera.EmulatedCamera`'s ``pose_noise``; pixel
noise, blur and lighting are :class:`pectoral_gym.hardware.vision.scene.SceneConditions`.
"""

from __future__ import annotations

import collections
import math
import time

import cv2
import numpy as np

from pectoral_gym.hardware.clock import REAL_CLOCK, Clock
from pectoral_gym.hardware.vision.frames import Frame, FrameSource

__all__ = ["FREEZE_MODES", "FaultyCamera"]

FREEZE_MODES = (None, "repeat", "cycle", "overlay", "noisy")


class FaultyCamera:
    """A :class:`FrameSource` that degrades another one (see the module docstring for each fault).

    Args:
        source: The live frame source.
        drop: Probability of losing each frame, in [0, 1].
        freeze: One of :data:`FREEZE_MODES`.
        cycle: Number of buffers a ``"cycle"`` freeze goes round (the last ``cycle`` live images), >= 1.
        noise: Standard deviation of the fresh noise of a ``"noisy"`` freeze [grey levels] (seeded by ``seed``).
        clock_offset: Added to every stamp [s].
        latency: Extra delay from the source's delivery to ``read()`` handing the frame out [s], >= 0.
        block: Time each ``read()`` blocks before reading [s], >= 0 (``math.inf``: until ``close()``).
        seed: Seed of the drop generator.
        clock: The clock ``latency`` and ``block`` count on (:mod:`pectoral_gym.hardware.clock`).

    Attributes:
        delivered: Frames handed out; ``dropped``: frames lost to ``drop``.
    """

    def __init__(self, source: FrameSource, drop: float = 0.0, freeze: str | None = None, cycle: int = 4,
                 clock_offset: float = 0.0, latency: float = 0.0, block: float = 0.0, seed: int | None = None,
                 clock: Clock = REAL_CLOCK, noise: float = 2.0):
        if int(cycle) != cycle or cycle < 1:
            raise ValueError(f"cycle must be an integer >= 1, got {cycle!r}")
        self.source = source
        self.drop, self.freeze, self.clock_offset, self.latency, self.block = drop, freeze, clock_offset, latency, block
        self._rng = np.random.default_rng(seed)
        self.noise = float(noise)
        self._live: collections.deque[np.ndarray] = collections.deque(maxlen=int(cycle))
        self._frozen: list[np.ndarray] = []
        self._turn = 0
        self._pending: collections.deque[tuple[float, Frame]] = collections.deque()
        self.clock = clock
        self._closed = clock.event()
        self.delivered = self.dropped = 0

    def __setattr__(self, name: str, value) -> None:
        if name == "drop" and not (isinstance(value, (int, float)) and 0 <= value <= 1):
            raise ValueError(f"drop must be a probability in [0, 1], got {value!r}")
        if name == "freeze" and value not in FREEZE_MODES:
            raise ValueError(f"freeze must be one of {FREEZE_MODES}, got {value!r}")
        if name == "clock_offset" and not (isinstance(value, (int, float)) and math.isfinite(value)):
            raise ValueError(f"clock_offset must be a finite number of seconds, got {value!r}")
        if name in ("latency", "block") and not (isinstance(value, (int, float)) and value >= 0):
            raise ValueError(f"{name} must be a number of seconds >= 0, got {value!r}")
        if name == "freeze" and value != getattr(self, "freeze", None):
            self.__dict__["_frozen"] = []  # the images to repeat are taken at the first frozen frame
        super().__setattr__(name, value)

    def read(self) -> Frame | None:
        """The next degraded frame, or ``None`` (nothing new, dropped, delayed, or closed)."""
        if self.block > 0 and self._closed.wait(self.block if math.isfinite(self.block) else None):
            return None
        if self._closed.is_set():
            return None
        frame = self.source.read()
        now = self.clock.monotonic()
        if frame is not None and self.drop > 0 and self._rng.random() < self.drop:
            self.dropped += 1
            frame = None
        if frame is not None:
            self._pending.append((now, self._degrade(frame)))
        ready = None
        while self._pending and self._pending[0][0] + self.latency <= now:
            ready = self._pending.popleft()[1]
        if ready is not None:
            self.delivered += 1
        return ready

    def _degrade(self, frame: Frame) -> Frame:
        if self.freeze is None:
            self._live.append(frame.image.copy())
            image = frame.image
        else:
            if not self._frozen:
                self._frozen = list(self._live) or [frame.image.copy()]
                self._turn = 0
            if self.freeze == "cycle":
                image = self._frozen[self._turn % len(self._frozen)]
                self._turn += 1
            else:
                image = self._frozen[-1]
            if self.freeze == "noisy":
                noisy = image + self._rng.normal(0.0, self.noise, image.shape)
                image = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
            if self.freeze == "overlay":
                image = image.copy()
                clock = time.strftime("%H:%M:%S") + f".{int(frame.timestamp * 1000) % 1000:03d}"
                cv2.putText(image, clock, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
        return Frame(image, frame.timestamp + self.clock_offset)

    def close(self) -> None:
        """Release a blocked ``read()`` and close the source (safe to call twice)."""
        self._closed.set()
        self.source.close()
