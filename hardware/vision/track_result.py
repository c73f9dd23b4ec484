"""What the marker tracker (:mod:`pectoral_gym.hardware.vision.tracker`) reports: its blobs, its result per frame.

In a module of their own so that the overlay, which draws them, and the tracker, which makes them, import them
without importing each other.
"""

from __future__ import annotations

import inspect
from typing import NamedTuple

__all__ = ["Blob", "TrackResult", "check_tracker"]


class Blob(NamedTuple):
    """A connected region of one marker colour.

    Attributes:
        pixel: Centroid (u, v) [px].
        tank: Centroid on the tank plane (X, Y) [m].
        area: Area [px].
        area_ratio: Area over the expected marker area there.
        elongation: Ratio of principal axes (>= 1).
        reason: Why it is not a marker candidate ("" when it is).
    """

    pixel: tuple[float, float]
    tank: tuple[float, float]
    area: float
    area_ratio: float
    elongation: float
    reason: str


class TrackResult(NamedTuple):
    """Outcome of tracking one frame; pose fields are NaN unless ``ok``.

    Attributes:
        ok: A pose was found.
        x: Centre of mass X [m].
        y: Centre of mass Y [m].
        psi: Heading in (-pi, pi] [rad], back marker -> front marker.
        confidence: 0..1, the smallest margin of marker size, roundness and spacing to their rejection
            thresholds (1 nominal, 0 at a threshold); halved when a distractor of marker colour is in view.
        timestamp: The frame's timestamp [s].
        reason: Why not ok ("" when ok).
        box: Pixel box ``(row0, row1, col0, col1)``, end exclusive, clipped to the image, that holds the
            whole fish (:func:`~pectoral_gym.hardware.vision.fishbox.fish_box` with
            :data:`~pectoral_gym.hardware.vision.fishbox.BOX_MARGIN`); ``None`` unless ``ok``. The region
            ``pectoral_gym.hardware.vision.framecheck.FrameCheck.check`` compares between frames.
    """

    ok: bool
    x: float
    y: float
    psi: float
    confidence: float
    timestamp: float
    reason: str
    box: tuple[int, int, int, int] | None = None


def check_tracker(tracker: object) -> None:
    """Check that ``tracker`` can be called as the supervisor calls it: ``tracker.track(frame, near=box)``.

    ``near`` is the last sighting's box ``(u0, v0, u1, v1)`` [px] while the fish is seen, else ``None``; the call
    returns a :class:`TrackResult`. A ``track`` whose signature cannot be read is judged at its first call (a
    tracker that raises there stops the fish with the error as the reason).

    Raises:
        TypeError: ``tracker`` has no ``track`` method, or its ``track`` does not take ``(frame, near=...)``.
    """
    name = type(tracker).__name__
    track = getattr(tracker, "track", None)
    if not callable(track):
        raise TypeError(f"a tracker needs a method track(frame, near=None) -> TrackResult; {name} has none")
    try:
        signature = inspect.signature(track)
    except (TypeError, ValueError):
        return
    try:
        signature.bind(None, near=None)
    except TypeError as error:
        raise TypeError(f"{name}.track must take track(frame, near=None) -> TrackResult (near: the last sighting's "
                        f"box (u0, v0, u1, v1) in pixels, or None): {error}") from None
