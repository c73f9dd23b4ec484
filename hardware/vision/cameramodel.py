"""Camera model of the overhead camera: a plane-to-image homography (tank metres -> pixels) of the marker plane.

The tank frame is the simulation's (:mod:`pectoral_gym.hardware.vision.scene`); pixel coordinates follow OpenCV:
``u`` to the right, ``v`` down, pixel centres at integer coordinates.
"""

from __future__ import annotations

import functools
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH

__all__ = ["CameraModel", "fit_homography"]


def _as_points(xy: np.ndarray | tuple | list, name: str) -> np.ndarray:
    points = np.asarray(xy, dtype=float)
    if points.shape[-1:] != (2,):
        raise ValueError(f"{name} must have shape (..., 2), got {points.shape}")
    if not np.all(np.isfinite(points)):
        raise ValueError(f"{name} must be finite, got {points!r}")
    return points


def _apply_homography(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    homogeneous = points @ matrix[:, :2].T
    if homogeneous.size < 96:
        homogeneous += matrix[:, 2]
        return homogeneous[..., :2] / homogeneous[..., 2:3]
    # The same sums and quotients column by column: numpy's broadcast over the last, short axis is slower
    columns = homogeneous.reshape(-1, 3)
    weight = columns[:, 2] + matrix[2, 2]
    result = np.empty((len(columns), 2))
    for axis in (0, 1):
        np.add(columns[:, axis], matrix[axis, 2], out=result[:, axis])
        np.divide(result[:, axis], weight, out=result[:, axis])
    return result.reshape(points.shape)


def fit_homography(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Least-squares homography (3x3) mapping ``source`` (n, 2) points to ``target`` (n, 2), n >= 4.

    Normalised direct linear transform (Hartley and Zisserman, Alg. 4.2) in float64: exact for exact points.

    Raises:
        ValueError: Fewer than 4 pairs, mismatched shapes, non-finite values, or a degenerate layout
            (three or more of four points on a line leave the homography undetermined).
    """
    src, dst = np.asarray(source, dtype=float), np.asarray(target, dtype=float)
    if src.ndim != 2 or src.shape[1] != 2 or src.shape != dst.shape:
        raise ValueError(f"need matching (n, 2) point arrays, got {src.shape} and {dst.shape}")
    if len(src) < 4:
        raise ValueError(f"a homography needs at least 4 point pairs, got {len(src)}")
    if not (np.all(np.isfinite(src)) and np.all(np.isfinite(dst))):
        raise ValueError("homography points must be finite")

    def normaliser(points: np.ndarray) -> np.ndarray:
        centre = points.mean(axis=0)
        spread = np.sqrt(2) / max(np.linalg.norm(points - centre, axis=1).mean(), 1e-300)
        return np.array([[spread, 0, -spread * centre[0]], [0, spread, -spread * centre[1]], [0, 0, 1]])

    t_src, t_dst = normaliser(src), normaliser(dst)
    p = _apply_homography(t_src, src)
    q = _apply_homography(t_dst, dst)
    rows = []
    for (x, y), (u, v) in zip(p, q, strict=True):
        rows.append([x, y, 1, 0, 0, 0, -u * x, -u * y, -u])
        rows.append([0, 0, 0, x, y, 1, -v * x, -v * y, -v])
    _, singular, vt = np.linalg.svd(np.array(rows))
    if singular[7] < 1e-9 * singular[0]:
        raise ValueError("the points do not determine a homography (are three of them on one line?)")
    matrix = np.linalg.inv(t_dst) @ vt[-1].reshape(3, 3) @ t_src
    if abs(matrix[2, 2]) < 1e-300 or abs(np.linalg.det(matrix / matrix[2, 2])) < 1e-12:
        raise ValueError("the points do not determine a homography (are three of them on one line?)")
    return matrix / matrix[2, 2]


@dataclass(frozen=True, eq=False)
class CameraModel:
    """A pinhole camera looking down on the marker plane, as a homography.

    Attributes:
        width: Image width [px].
        height: Image height [px].
        homography: 3x3 matrix mapping homogeneous tank coordinates [m] to pixels (read-only copy).
    """

    width: int
    height: int
    homography: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        if int(self.width) != self.width or int(self.height) != self.height or self.width < 8 or self.height < 8:
            raise ValueError(f"CameraModel: width and height must be integers >= 8, got {self.width}x{self.height}")
        matrix = np.array(self.homography, dtype=float)
        if matrix.shape != (3, 3) or not np.all(np.isfinite(matrix)):
            raise ValueError(f"CameraModel: homography must be a finite 3x3 matrix, got {matrix!r}")
        if abs(np.linalg.det(matrix)) < 1e-12 * max(1.0, np.abs(matrix).max() ** 3):
            raise ValueError("CameraModel: homography is singular")
        matrix /= matrix[2, 2] if matrix[2, 2] != 0 else 1.0
        matrix.setflags(write=False)
        inverse = np.linalg.inv(matrix)
        inverse.setflags(write=False)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        object.__setattr__(self, "homography", matrix)
        object.__setattr__(self, "_inverse", inverse)

    @property
    def inverse(self) -> np.ndarray:
        """The 3x3 pixel -> tank homography (read-only)."""
        return self._inverse  # type: ignore[attr-defined]

    def tank_to_pixel(self, xy: np.ndarray | tuple | list) -> np.ndarray:
        """Project tank points ``(..., 2)`` [m] to pixel coordinates ``(..., 2)`` (u, v)."""
        return _apply_homography(self.homography, _as_points(xy, "xy"))

    def pixel_to_tank(self, uv: np.ndarray | tuple | list) -> np.ndarray:
        """Back-project pixel coordinates ``(..., 2)`` onto the tank plane ``(..., 2)`` [m]."""
        return _apply_homography(self.inverse, _as_points(uv, "uv"))

    def pixels_per_metre(self, xy: np.ndarray | tuple | list) -> float:
        """Local image scale [px/m] at a tank point (geometric mean of the two axes)."""
        centre = _as_points(xy, "xy")
        step = 1e-3
        project = functools.partial(_apply_homography, self.homography)  # centre is checked: finite
        du = project(centre + (step, 0.0)) - project(centre - (step, 0.0))
        dv = project(centre + (0.0, step)) - project(centre - (0.0, step))
        return float(np.sqrt(abs(du[0] * dv[1] - du[1] * dv[0])) / (2 * step))

    def to_dict(self) -> dict[str, Any]:
        """The calibration-file fields: ``homography`` (3x3 nested list), ``width``, ``height``."""
        return {"homography": self.homography.tolist(), "width": self.width, "height": self.height}

    def save(self, path: str | os.PathLike, **extra: Any) -> None:
        """Write the calibration JSON (``homography``, ``width``, ``height`` and any ``extra`` keys)."""
        Path(path).write_text(json.dumps({**self.to_dict(), **extra}, indent=2) + "\n")

    @classmethod
    def load(cls, path: str | os.PathLike) -> CameraModel:
        """Read a calibration JSON written by ``python -m pectoral_gym.hardware.calibrate``.

        Raises:
            ValueError: The file is not a calibration (missing or malformed keys).
        """
        from pectoral_gym.inputfile import SMALL_FILE_BYTES, load_json

        try:
            data = load_json(path, SMALL_FILE_BYTES)  # bounded: a calibration is under 1 kB
            return cls(int(data["width"]), int(data["height"]), np.asarray(data["homography"], dtype=float))
        except (KeyError, TypeError, IndexError, OverflowError, ValueError) as error:
            raise ValueError(
                f"{path}: not a camera calibration (need JSON keys homography 3x3, width, height): {error}"
            ) from error

    @classmethod
    def from_corners(cls, width: int, height: int, corner_pixels: np.ndarray | list) -> CameraModel:
        """Build a camera from the pixel positions of the tank corners.

        Args:
            width: Image width [px].
            height: Image height [px].
            corner_pixels: (4, 2) pixels of the tank corners (0, 0), (L, 0), (L, W), (0, W).
        """
        pixels = _as_points(corner_pixels, "corner_pixels")
        if pixels.shape != (4, 2):
            raise ValueError(f"corner_pixels must have shape (4, 2), got {pixels.shape}")
        tank = np.array([[0.0, 0.0], [TANK_LENGTH, 0.0], [TANK_LENGTH, TANK_WIDTH], [0.0, TANK_WIDTH]])
        return cls(width, height, fit_homography(tank, pixels))

    @classmethod
    def default(cls) -> CameraModel:
        """A 640x360 overhead view of the whole tank, slightly tilted so that the far wall looks shorter.

        Tank Y points up in the image. About 260 px/m: the fish is ~50 px long, a marker ~8 px across. Every call
        returns the same (immutable) model: what is cached per camera model (the renderer's background and noise
        tables) is then made once per process, not once per emulated camera.
        """
        return _default_model(cls)


@functools.cache
def _default_model(cls: type[CameraModel]) -> CameraModel:
    """:meth:`CameraModel.default`'s model, made once per class."""
    corners = [[22.0, 338.0], [618.0, 338.0], [604.0, 26.0], [36.0, 26.0]]
    return cls.from_corners(640, 360, corners)
