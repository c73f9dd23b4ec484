"""Which camera frames count as a new sighting of the fish: a sane clock and new image content.

A frame source may hand out frames that look new but are not: stamped by another host's clock (far in
the future or the past), with a NaN or infinite stamp, stamped earlier than the last one, or a frozen
camera re-delivering its last image with fresh stamps. :class:`FrameCheck` rejects each with a
reason; a rejected frame counts as "fish not seen", so the tracking timeout stops the fins.

A real sensor never delivers two bit-identical images of a live scene (its noise alone differs), so an
exact repeat of the previous image is taken as frozen. The digest is BLAKE2b over the raw pixels
(about 1 ms for a 640 x 480 image).
"""

from __future__ import annotations

import hashlib
import math

import numpy as np

from hardware.frames import Frame

__all__ = ["FrameCheck", "FRAME_REASONS"]

FRAME_REASONS = ("bad_image", "bad_timestamp", "timestamp_backwards", "timestamp_future", "frame_too_old",
                 "frozen_frame")


class FrameCheck:
    """Classify frames on arrival.

    Args:
        max_lead: A stamp more than this ahead of ``now`` is rejected (``timestamp_future``) [s].
        max_age: A stamp more than this behind ``now`` is rejected (``frame_too_old``) [s].

    Attributes:
        last_timestamp: Stamp of the last accepted frame.
        rejected: Count per reason.
    """

    def __init__(self, max_lead: float, max_age: float):
        if not (max_lead >= 0 and max_age > 0):
            raise ValueError(f"need max_lead >= 0 and max_age > 0, got {max_lead!r}, {max_age!r}")
        self.max_lead, self.max_age = float(max_lead), float(max_age)
        self.last_timestamp: float | None = None
        self._last_digest: bytes | None = None
        self.rejected = dict.fromkeys(FRAME_REASONS, 0)

    def reset(self) -> None:
        """Forget the last frame (a new episode, or a camera that was re-opened)."""
        self.last_timestamp, self._last_digest = None, None

    def check(self, frame: Frame, now: float) -> str:
        """``""`` if ``frame`` is a new sighting at ``now`` (same clock as its stamp) [s], else the reason."""
        reason = self._reason(frame, now)
        if reason:
            self.rejected[reason] += 1
        return reason

    def _reason(self, frame: Frame, now: float) -> str:
        image = frame.image
        if not isinstance(image, np.ndarray) or image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            return "bad_image"
        try:
            t = float(frame.timestamp)
        except (TypeError, ValueError):
            return "bad_timestamp"
        if not math.isfinite(t):
            return "bad_timestamp"
        if self.last_timestamp is not None and t <= self.last_timestamp:
            return "timestamp_backwards"
        if t > now + self.max_lead:
            return "timestamp_future"
        if t < now - self.max_age:
            return "frame_too_old"
        digest = hashlib.blake2b(np.ascontiguousarray(image).data, digest_size=16).digest()
        frozen = digest == self._last_digest
        self._last_digest = digest
        self.last_timestamp = t  # a frozen frame still moves the clock on: its stamp was sane
        return "frozen_frame" if frozen else ""
