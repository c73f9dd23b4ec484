"""The pixel box that holds the whole fish: the region the frame checks compare and the tracker searches first."""

from __future__ import annotations

import math

import numpy as np

from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.scene import BODY_LENGTH

__all__ = ["BOX_MARGIN", "fish_box"]

BOX_MARGIN = 0.03  # m beyond the body's half length around the centre in ``TrackResult.box``
_RING_COS, _RING_SIN = np.cos(np.linspace(0.0, 2 * math.pi, 16, endpoint=False)), np.sin(
    np.linspace(0.0, 2 * math.pi, 16, endpoint=False))  # the 16 directions of fish_box's ring


def fish_box(camera: CameraModel, pose: tuple[float, ...], margin: float = BOX_MARGIN) -> tuple[int, int, int, int]:
    """Pixel box around a fish at ``pose``: the image of a tank disc of radius half a body length + ``margin``.

    Args:
        camera: The camera model.
        pose: ``(X, Y, ...)`` of the centre of mass [m]; the heading, if given, is not used (the disc
            holds the body at any heading).
        margin: Extra radius beyond half the body length [m], >= 0.

    Returns:
        ``(row0, row1, col0, col1)`` pixels, end exclusive, clipped to the image (may be empty, row0 ==
        row1, when the fish is outside the view).

    Raises:
        ValueError: A non-finite position or a negative margin.
    """
    if not (math.isfinite(margin) and margin >= 0):
        raise ValueError(f"margin must be a finite number >= 0 [m], got {margin!r}")
    x, y = float(pose[0]), float(pose[1])
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"pose position must be finite, got {pose!r}")
    radius = BODY_LENGTH / 2 + margin
    ring = np.stack([x + radius * _RING_COS, y + radius * _RING_SIN], axis=1)
    pixels = camera.tank_to_pixel(ring)
    col0, row0 = np.floor(pixels.min(axis=0)).astype(int) - 1
    col1, row1 = np.ceil(pixels.max(axis=0)).astype(int) + 2
    row0, row1 = min(max(int(row0), 0), camera.height), min(max(int(row1), 0), camera.height)
    col0, col1 = min(max(int(col0), 0), camera.width), min(max(int(col1), 0), camera.width)
    return row0, max(row1, row0), col0, max(col1, col0)
