"""A tracker's view drawn on a frame: the calibrated tank outline and grid, the blobs, the pose or the reason."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import cv2
import numpy as np

from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH

if TYPE_CHECKING:
    from pectoral_gym.hardware.vision.track_result import Blob, TrackResult

__all__ = ["draw_overlay"]


def draw_overlay(
    image: np.ndarray,
    camera: CameraModel,
    result: TrackResult | None = None,
    blobs: dict[str, list[Blob]] | None = None,
    grid: float = 0.25,
) -> np.ndarray:
    """A copy of ``image`` with the calibrated tank outline, a grid, the blobs and the tracked pose drawn on it.

    Args:
        image: (H, W, 3) uint8 BGR frame.
        camera: Camera model whose homography is checked by eye (the outline must sit on the tank walls).
        result: A tracking result: an arrow from the centre along the heading, or the reason when lost.
        blobs: ``MarkerTracker.last_blobs``: accepted blobs circled in green, rejected ones in grey.
        grid: Grid spacing [m] (0: no grid).
    """
    canvas = image.copy()

    def line(points: list[tuple[float, float]], colour: tuple[int, int, int], width: int) -> None:
        pixels = np.rint(camera.tank_to_pixel(np.array(points)) * 16).astype(np.int32)
        cv2.polylines(canvas, [pixels], False, colour, width, cv2.LINE_AA, shift=4)

    if grid > 0:
        for x in np.arange(grid, TANK_LENGTH, grid):
            line([(x, 0.0), (x, TANK_WIDTH)], (150, 150, 150), 1)
        for y in np.arange(grid, TANK_WIDTH, grid):
            line([(0.0, y), (TANK_LENGTH, y)], (150, 150, 150), 1)
    line([(0, 0), (TANK_LENGTH, 0), (TANK_LENGTH, TANK_WIDTH), (0, TANK_WIDTH), (0, 0)], (0, 200, 255), 2)
    for colour_blobs in (blobs or {}).values():
        for blob in colour_blobs:
            centre = (int(round(blob.pixel[0])), int(round(blob.pixel[1])))
            radius = int(round(math.sqrt(blob.area / math.pi))) + 3
            cv2.circle(canvas, centre, radius, (160, 160, 160) if blob.reason else (0, 220, 0), 1, cv2.LINE_AA)
    if result is not None and result.ok:
        tip = (result.x + 0.12 * math.cos(result.psi), result.y + 0.12 * math.sin(result.psi))
        start, end = np.rint(camera.tank_to_pixel(np.array([(result.x, result.y), tip]))).astype(int)
        cv2.arrowedLine(canvas, tuple(start.tolist()), tuple(end.tolist()), (0, 255, 255), 2, cv2.LINE_AA, 0, 0.3)
    elif result is not None:
        cv2.putText(canvas, f"lost: {result.reason}"[:90], (8, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 255), 1,
                    cv2.LINE_AA)
    return canvas
