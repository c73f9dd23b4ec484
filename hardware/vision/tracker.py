"""Fish pose from an overhead frame: colour segmentation of the red (front) and blue (back) markers.

Pipeline (paper Sec. 4.1, made defensive): BGR -> HSV; red is two hue bands because OpenCV's hue wraps at 180;
blue one band; both need enough saturation and value, which rejects the floor, walls, body and glare. Each mask
is cleaned by a morphological opening and closing, and its blobs are kept only if their area is near the area a
marker should have at that place in the image (from the homography) and they are round (ratio of the principal
axes). Blob centroids go through the pixel -> tank homography; among the surviving red x blue pairs, the one whose
separation matches the known marker spacing is the fish. A missing marker, an implausible blob or a tie between
candidates is reported as lost with the reason: the tracker never guesses.

The conversion, thresholds and cleanup run only on the box of the frame that can hold marker pixels (a
necessary saturation test on every pixel, cheaper than the conversion): the blobs are the whole frame's.
``track(frame, near=box)`` first runs that test only in a window around the last sighting's box: its pose is
the whole frame's whenever every candidate pixel of the frame lies inside the window; it is taken only when no
candidate reaches the window's edge and it is a pose, otherwise the whole frame is searched (see ``track``).
"""

from __future__ import annotations

import math
import os
import threading
from dataclasses import dataclass

import cv2
import numpy as np

from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.fishbox import BOX_MARGIN, fish_box
from pectoral_gym.hardware.vision.frames import Frame
from pectoral_gym.hardware.vision.overlay import draw_overlay
from pectoral_gym.hardware.vision.scene import BACK_MARKER_OFFSET, FRONT_MARKER_OFFSET, MARKER_RADIUS
from pectoral_gym.hardware.vision.track_result import Blob, TrackResult

__all__ = ["BOX_MARGIN", "Blob", "MarkerTracker", "TrackResult", "TrackerConfig", "draw_overlay", "fish_box"]

NEAR_MARGIN = 12  # px around the last sighting's box searched first (a fish moving under ~1 m/s stays inside)
_PREFILTER_MIN_SATURATION = 86  # lowest min_saturation for which MarkerTracker._candidates' test holds


@dataclass(frozen=True)
class TrackerConfig:
    """Segmentation and plausibility thresholds. Hues are OpenCV's 0-179 scale (degrees / 2).

    Attributes:
        red_hue_bands: Hue bands of the red marker; two because red straddles the 0/180 wrap.
        blue_hue_bands: Hue bands of the blue marker.
        min_saturation: Lowest saturation (0-255) of a marker pixel; the floor, walls and glare sit far below.
        min_value: Lowest value (0-255) of a marker pixel; dark shadows are not markers.
        kernel_size: Side of the square structuring element of the morphological cleanup [px].
        min_area_ratio: Smallest blob area as a fraction of a marker's expected area (partly hidden -> lost).
        max_area_ratio: Largest blob area as a multiple of the expected area (a red object -> rejected).
        max_elongation: Largest ratio of a blob's principal axes (a disc is 1, a quarter hidden ~1.3).
        front_offset: Red marker position along body x from the centre of mass [m].
        back_offset: Blue marker position along body x [m].
        marker_radius: Marker radius [m] (sets the expected area).
        separation_tolerance: Largest |measured - nominal| marker distance [m].
        ambiguity_margin: A second pair whose separation error is within this of the best one's is a tie [m].
    """

    red_hue_bands: tuple[tuple[int, int], ...] = ((0, 10), (170, 179))
    blue_hue_bands: tuple[tuple[int, int], ...] = ((95, 130),)
    min_saturation: int = 110
    min_value: int = 30
    kernel_size: int = 3
    min_area_ratio: float = 0.85
    max_area_ratio: float = 1.8
    max_elongation: float = 1.3
    front_offset: float = FRONT_MARKER_OFFSET
    back_offset: float = BACK_MARKER_OFFSET
    marker_radius: float = MARKER_RADIUS
    separation_tolerance: float = 0.02
    ambiguity_margin: float = 0.01

    def __post_init__(self) -> None:
        for bands, name in ((self.red_hue_bands, "red_hue_bands"), (self.blue_hue_bands, "blue_hue_bands")):
            if not bands or any(not (0 <= low <= high <= 179) for low, high in bands):
                raise ValueError(f"TrackerConfig.{name}: need bands (low, high) with 0 <= low <= high <= 179")
        if not self.front_offset > self.back_offset:
            raise ValueError("TrackerConfig: front_offset must be ahead of back_offset")
        if not 0 < self.min_area_ratio < 1 < self.max_area_ratio:
            raise ValueError("TrackerConfig: need 0 < min_area_ratio < 1 < max_area_ratio")
        if self.kernel_size < 1 or self.marker_radius <= 0 or self.separation_tolerance <= 0:
            raise ValueError("TrackerConfig: kernel_size, marker_radius and separation_tolerance must be > 0")

    @property
    def separation(self) -> float:
        """Nominal distance between the marker centres [m]."""
        return self.front_offset - self.back_offset


def _covariance(us: np.ndarray, vs: np.ndarray) -> np.ndarray:
    """``np.cov(np.stack([us, vs]))``, its very operations without its argument handling (the same bits)."""
    samples = np.stack([us, vs])
    samples -= samples.mean(axis=1)[:, None]
    covariance = np.dot(samples, samples.T.conj())
    covariance *= np.true_divide(1, samples.shape[1] - 1)
    return covariance


def _lost(timestamp: float, reason: str) -> TrackResult:
    return TrackResult(False, math.nan, math.nan, math.nan, 0.0, timestamp, reason)


class MarkerTracker:
    """Finds the fish's pose in frames of a calibrated overhead camera.

    Args:
        camera: Camera model (pixel <-> tank homography), e.g. ``CameraModel.load("calibration.json")``.
        config: Thresholds; ``None`` means :class:`TrackerConfig` defaults.
    """

    def __init__(self, camera: CameraModel, config: TrackerConfig | None = None) -> None:
        self.camera = camera
        self.config = TrackerConfig() if config is None else config
        size = self.config.kernel_size
        self._kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
        self.last_blobs: dict[str, list[Blob]] = {"red": [], "blue": []}
        self._planes = threading.local()  # per thread: the colour planes of _candidates, reused frame after frame

    @classmethod
    def from_calibration(cls, path: str | os.PathLike, config: TrackerConfig | None = None) -> MarkerTracker:
        """A tracker for the camera described by a calibration JSON file."""
        return cls(CameraModel.load(path), config)

    def _plane_buffers(self, height: int, width: int) -> list[np.ndarray]:
        """Three ``(height, width)`` uint8 planes of this thread, made once per frame size.

        ``cv2.split`` into planes it allocates costs several times the split itself (three fresh arrays of a
        frame's size each frame); the planes are scratch, read only inside :meth:`_candidates`.
        """
        planes = getattr(self._planes, "buffers", None)
        if planes is None or planes[0].shape != (height, width):
            planes = [np.empty((height, width), np.uint8) for _ in range(3)]
            self._planes.buffers = planes
        return planes

    def _candidates(self, image: np.ndarray) -> tuple[int, int, int, int] | None:
        """Pixel box ``(row0, row1, col0, col1)`` outside which no pixel can pass a marker mask; ``None``: none.

        A pixel passes only with saturation ``S >= min_saturation`` and value ``V = max(B, G, R) >= min_value``.
        OpenCV's 8-bit ``S`` is ``255 (V - min) / V`` rounded, so ``S >= 86`` implies ``3 (V - min) >= V``
        (tests/test_tracker_crop.py checks all 2^24 colours), a test of a few byte-wide operations, cheaper than
        the HSV conversion. The box has a margin that keeps the morphological cleanup's result inside it exact.
        """
        cfg = self.config
        height, width = image.shape[:2]
        if cfg.min_saturation < _PREFILTER_MIN_SATURATION:
            return 0, height, 0, width
        blue, green, red = cv2.split(image, self._plane_buffers(height, width))
        high = cv2.max(cv2.max(blue, green), red)
        spread = cv2.subtract(high, cv2.min(cv2.min(blue, green), red))
        spread = cv2.add(cv2.add(spread, spread), spread)  # saturates at 255 >= V: still a candidate, rightly
        candidates = cv2.compare(spread, cv2.max(high, float(cfg.min_value)), cv2.CMP_GE)
        return self._crop(cv2.boundingRect(candidates), (0, 0), height, width)

    def _near(self, image: np.ndarray, window: tuple[int, int, int, int]
              ) -> tuple[tuple[int, int, int, int], np.ndarray] | None:
        """The crop of the pixels of ``window`` that can pass a marker mask, and its HSV; ``None``: search the frame.

        In a window of a few thousand pixels the HSV conversion is cheaper than :meth:`_candidates`' test (fewer
        calls), and the test is then exact: ``S >= min_saturation`` and ``V >= min_value``. ``None`` when no pixel
        of the window passes it or one lies within the crop's margin of an edge of the window inside the frame.
        """
        cfg = self.config
        height, width = image.shape[:2]
        row0, row1, col0, col1 = window
        hsv = cv2.cvtColor(image[row0:row1, col0:col1], cv2.COLOR_BGR2HSV)
        passing = cv2.inRange(hsv, (0, cfg.min_saturation, cfg.min_value), (255, 255, 255))
        u, v, w, h = cv2.boundingRect(passing)
        margin = self._margin()
        # The candidates must keep the crop's margin from every edge of the window inside the frame: then the crop
        # lies in the window, and within the margin of its candidates the whole frame has none either (whatever
        # lies beyond the window is farther), so the cleanup and the blobs in the crop are the whole frame's.
        if w == 0 or (v < margin and row0 > 0) or (u < margin and col0 > 0) or (
                row1 - row0 - v - h < margin and row1 < height) or (col1 - col0 - u - w < margin and col1 < width):
            return None  # the fish is not in the window, or may reach beyond it
        crop = self._crop((u, v, w, h), (col0, row0), height, width)
        assert crop is not None  # w > 0
        return crop, hsv[crop[0] - row0 : crop[1] - row0, crop[2] - col0 : crop[3] - col0]

    def _margin(self) -> int:
        """Empty border around the candidates in a crop [px].

        Opening and closing each reach kernel_size // 2 pixels; a border of more than twice that keeps every pixel
        of the cleaned crop as in the whole frame (OpenCV's default border is neutral for both).
        """
        return 2 * self.config.kernel_size + 2

    def _crop(self, rect: tuple[int, int, int, int], origin: tuple[int, int], height: int, width: int
              ) -> tuple[int, int, int, int] | None:
        """The box of the candidates' bounding ``rect`` (found in a window at ``origin`` = (col, row)) with margin."""
        u, v, w, h = rect
        if w == 0:
            return None
        u, v, margin = u + origin[0], v + origin[1], self._margin()
        return max(v - margin, 0), min(v + h + margin, height), max(u - margin, 0), min(u + w + margin, width)

    def _mask(self, hsv: np.ndarray, bands: tuple[tuple[int, int], ...]) -> np.ndarray:
        cfg = self.config
        mask = np.zeros(hsv.shape[:2], np.uint8)
        for low, high in bands:
            mask |= cv2.inRange(hsv, (low, cfg.min_saturation, cfg.min_value), (high, 255, 255))
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._kernel)
        return cv2.morphologyEx(mask, cv2.MORPH_CLOSE, self._kernel)

    def _blobs(self, mask: np.ndarray, origin: tuple[int, int] = (0, 0)) -> list[Blob]:
        """Blobs of ``mask``, a crop of the frame whose top-left pixel is ``origin`` = (col, row)."""
        cfg = self.config
        points = cv2.findNonZero(mask)
        if points is None:
            return []
        # Labelled within the box of the mask's pixels only: the same components, in the same (raster) order, with
        # the same pixels, as over the whole image, for a fraction of the cost (most of the mask is empty).
        cu, cv, cw, ch = cv2.boundingRect(points)
        count, labels, stats, _ = cv2.connectedComponentsWithStats(mask[cv:cv + ch, cu:cu + cw], connectivity=8)
        cu, cv = cu + origin[0], cv + origin[1]
        blobs = []
        for label in range(1, count):
            x0, y0, w, h, area = stats[label]
            vs, us = np.nonzero(labels[y0 : y0 + h, x0 : x0 + w] == label)
            us, vs = us + float(x0 + cu), vs + float(y0 + cv)
            centre = (float(us.mean()), float(vs.mean()))
            eigen = np.linalg.eigvalsh(_covariance(us, vs)) if area > 2 else np.array([0.0, 1.0])
            elongation = float(np.sqrt(eigen[1] / max(eigen[0], 1e-9)))
            tank = self.camera.pixel_to_tank(centre)
            expected = math.pi * (cfg.marker_radius * self.camera.pixels_per_metre(tank)) ** 2
            ratio = float(area / expected)
            reason = ""
            if ratio < cfg.min_area_ratio:
                reason = f"area {area} px < {cfg.min_area_ratio:.2f} x expected {expected:.0f} px (hidden or too small)"
            elif ratio > cfg.max_area_ratio:
                reason = f"area {area} px > {cfg.max_area_ratio:.2f} x expected {expected:.0f} px (too large)"
            elif elongation > cfg.max_elongation:
                reason = f"elongation {elongation:.2f} > {cfg.max_elongation:.2f} (not a round marker)"
            blobs.append(Blob(centre, (float(tank[0]), float(tank[1])), float(area), ratio, elongation, reason))
        return blobs

    @staticmethod
    def _explain(colour: str, blobs: list[Blob]) -> str:
        if not blobs:
            return f"{colour} marker not found"
        if len(blobs) == 1:
            return f"{colour} marker rejected: {blobs[0].reason}"
        return f"{colour} marker: {len(blobs)} blobs, none plausible (first: {blobs[0].reason})"

    def _margins(self, blob: Blob) -> tuple[float, float]:
        """Normalised distances of a blob's size and shape to their rejection thresholds (1 nominal, 0 at one)."""
        cfg = self.config
        if blob.area_ratio < 1:
            size = (blob.area_ratio - cfg.min_area_ratio) / (1 - cfg.min_area_ratio)
        else:
            size = (cfg.max_area_ratio - blob.area_ratio) / (cfg.max_area_ratio - 1)
        shape = (cfg.max_elongation - blob.elongation) / (cfg.max_elongation - 1)
        return size, shape

    def track(self, frame: Frame, near: tuple[int, int, int, int] | None = None) -> TrackResult:
        """Pose of the fish in ``frame``, or a lost result saying why.

        A frame whose size differs from the calibration's is lost with a reason naming both sizes (a
        homography is only valid at the resolution it was measured at).

        Args:
            frame: The frame.
            near: The last sighting's box (:attr:`TrackResult.box`), or ``None``. The window :data:`NEAR_MARGIN`
                pixels around it is searched first, and its pose is the result when the window's candidate
                pixels keep a margin from its edges and make a pose: the pose the whole frame gives whenever
                the frame has no marker-coloured pixels outside the window (a second object there is not
                looked at). Otherwise, and without ``near``, the whole frame is searched.

        Raises:
            ValueError: ``frame.image`` is not an (H, W, 3) uint8 array.
        """
        image, timestamp = frame
        if not isinstance(image, np.ndarray) or image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            raise ValueError(f"frame.image must be an (H, W, 3) uint8 BGR array, got {getattr(image, 'shape', image)}")
        if image.shape[:2] != (self.camera.height, self.camera.width):
            return _lost(timestamp, f"frame is {image.shape[1]}x{image.shape[0]} px but the calibration is for "
                                    f"{self.camera.width}x{self.camera.height} px; recalibrate or set the camera "
                                    "resolution")
        if near is not None:
            row0, row1, col0, col1 = (int(edge) for edge in near)
            height, width = image.shape[:2]
            window = (max(row0 - NEAR_MARGIN, 0), min(row1 + NEAR_MARGIN, height),
                      max(col0 - NEAR_MARGIN, 0), min(col1 + NEAR_MARGIN, width))
            found = self._near(image, window) if window[0] < window[1] and window[2] < window[3] else None
            result = self._track(image, timestamp, *found) if found else None
            if result is not None and result.ok:
                return result
        return self._track(image, timestamp, self._candidates(image))

    def _track(self, image: np.ndarray, timestamp: float, crop: tuple[int, int, int, int] | None,
               hsv: np.ndarray | None = None) -> TrackResult:
        """The pose from the blobs inside ``crop`` (``None``: no pixel can be a marker's), whose HSV ``hsv`` is."""
        cfg = self.config
        blobs: dict[str, list[Blob]] = {"red": [], "blue": []}
        if crop is not None:  # else no pixel of the frame can be a marker's
            row0, row1, col0, col1 = crop
            hsv = cv2.cvtColor(image[row0:row1, col0:col1], cv2.COLOR_BGR2HSV) if hsv is None else hsv
            blobs = {"red": self._blobs(self._mask(hsv, cfg.red_hue_bands), (col0, row0)),
                     "blue": self._blobs(self._mask(hsv, cfg.blue_hue_bands), (col0, row0))}
        self.last_blobs = blobs
        reds = [b for b in blobs["red"] if not b.reason]
        blues = [b for b in blobs["blue"] if not b.reason]
        if not reds:
            return _lost(timestamp, self._explain("red (front)", blobs["red"]))
        if not blues:
            return _lost(timestamp, self._explain("blue (back)", blobs["blue"]))
        pairs = []
        for red in reds:
            for blue in blues:
                error = abs(math.dist(red.tank, blue.tank) - cfg.separation)
                if error <= cfg.separation_tolerance:
                    pairs.append((error, red, blue))
        if not pairs:
            distances = ", ".join(f"{math.dist(r.tank, b.tank) * 1000:.0f}" for r in reds for b in blues)
            return _lost(
                timestamp,
                f"marker separation {distances} mm, expected {cfg.separation * 1000:.0f} "
                f"+- {cfg.separation_tolerance * 1000:.0f} mm",
            )
        pairs.sort(key=lambda pair: pair[0])
        if len(pairs) > 1 and pairs[1][0] - pairs[0][0] < cfg.ambiguity_margin:
            return _lost(timestamp, f"ambiguous: {len(pairs)} red/blue pairs at a plausible separation")
        error, red, blue = pairs[0]
        front, back = np.array(red.tank), np.array(blue.tank)
        axis = (front - back) / np.linalg.norm(front - back)
        # Each marker gives the centre as marker - offset * axis; average the two estimates.
        centre = 0.5 * (front + back) - 0.5 * (cfg.front_offset + cfg.back_offset) * axis
        psi = math.atan2(axis[1], axis[0])
        # Confidence: the smallest normalised margin to any rejection threshold.
        confidence = min(*self._margins(red), *self._margins(blue), 1.0 - error / cfg.separation_tolerance)
        confidence = float(np.clip(confidence, 0.0, 1.0))
        if len(reds) > 1 or len(blues) > 1:
            confidence *= 0.5  # a distractor of marker colour and size is in view
        box = fish_box(self.camera, (float(centre[0]), float(centre[1])))
        return TrackResult(True, float(centre[0]), float(centre[1]), psi, float(confidence), float(timestamp), "", box)

