"""Overhead camera model and a renderer of what that camera sees of the tank and the fish.

The tank frame is the simulation's: origin at one corner of the ``TANK_LENGTH x TANK_WIDTH`` swimming area,
X along the length, Y along the width, heading ``psi`` from +X towards +Y, all in metres and radians.
A :class:`CameraModel` is a plane-to-image homography (tank metres -> pixels) of the marker plane; pixel
coordinates follow OpenCV: ``u`` to the right, ``v`` down, pixel centres at integer coordinates.

The fish is drawn as an ellipse of ``FishParams().body_length`` by :data:`BODY_WIDTH` with a red disc marker of
radius :data:`MARKER_RADIUS` at :data:`FRONT_MARKER_OFFSET` and a blue one at :data:`BACK_MARKER_OFFSET` along the
body x axis. Shapes are anti-aliased by supersampling so marker centroids are sub-pixel accurate, then the
imperfections of :class:`SceneConditions` (lighting, occlusion, blur, noise, glare) are applied. Rendering is
deterministic given the generator.
"""

from __future__ import annotations

import functools
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH, FishParams

__all__ = [
    "BACK_MARKER_OFFSET",
    "BODY_WIDTH",
    "FRONT_MARKER_OFFSET",
    "MARKER_RADIUS",
    "CameraModel",
    "Occluder",
    "SceneConditions",
    "fit_homography",
    "render_frame",
]

BODY_LENGTH = FishParams().body_length  # m, drawn ellipse length (one source: FishParams)
BODY_WIDTH = 0.07  # m, drawn ellipse width (fin pivots sit at +-fin_offset = 0.03 m)
FRONT_MARKER_OFFSET = 0.06  # m along body x from the centre of mass: centre of the red marker
BACK_MARKER_OFFSET = -0.06  # m along body x from the centre of mass: centre of the blue marker
MARKER_RADIUS = 0.015  # m, both markers are discs of 30 mm diameter

# Colours, BGR uint8 as OpenCV stores them.
FLOOR_BGR = (205, 200, 190)  # light grey-blue tank floor
WALL_BGR = (70, 70, 75)  # dark tank walls / outside the swimming area
BODY_BGR = (80, 95, 105)  # dark grey-olive body
RED_BGR = (40, 35, 205)  # red marker, hue ~2 deg (OpenCV hue ~1)
BLUE_BGR = (190, 90, 25)  # blue marker, hue ~205 deg (OpenCV hue ~103)
OCCLUDER_BGR = (45, 45, 50)  # dark occluding object (a hand, a cable, its shadow)

_SUPERSAMPLE = 4  # samples per pixel side for anti-aliased shapes


def _as_points(xy: np.ndarray | tuple | list, name: str) -> np.ndarray:
    points = np.asarray(xy, dtype=float)
    if points.shape[-1:] != (2,):
        raise ValueError(f"{name} must have shape (..., 2), got {points.shape}")
    if not np.all(np.isfinite(points)):
        raise ValueError(f"{name} must be finite, got {points!r}")
    return points


def _apply_homography(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    homogeneous = points @ matrix[:, :2].T + matrix[:, 2]
    return homogeneous[..., :2] / homogeneous[..., 2:3]


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
        du = self.tank_to_pixel(centre + (step, 0.0)) - self.tank_to_pixel(centre - (step, 0.0))
        dv = self.tank_to_pixel(centre + (0.0, step)) - self.tank_to_pixel(centre - (0.0, step))
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
        try:
            data = json.loads(Path(path).read_text())
            return cls(int(data["width"]), int(data["height"]), np.asarray(data["homography"], dtype=float))
        except (KeyError, TypeError, json.JSONDecodeError) as error:
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

        Tank Y points up in the image. About 260 px/m: the fish is ~50 px long, a marker ~8 px across.
        """
        corners = [[22.0, 338.0], [618.0, 338.0], [604.0, 26.0], [36.0, 26.0]]
        return cls.from_corners(640, 360, corners)


@dataclass(frozen=True)
class Occluder:
    """A dark disc above the water in tank coordinates (a hand, a cable, a distractor if coloured).

    Attributes:
        x: Centre X [m].
        y: Centre Y [m].
        radius: Radius [m].
        bgr: Colour (BGR, 0-255); a red or blue one is a distracting blob for the tracker.
    """

    x: float
    y: float
    radius: float
    bgr: tuple[int, int, int] = OCCLUDER_BGR


@dataclass(frozen=True)
class SceneConditions:
    """Imperfections of a camera frame. The defaults are a mildly noisy, evenly lit, sharp frame.

    Attributes:
        noise_std: Standard deviation of additive Gaussian sensor noise [intensity units, 0-255].
        brightness: Overall gain of the lighting (1 = nominal; 0.5 = dim, 1.3 = bright).
        gradient: Relative gain change from the image centre to its edge along ``gradient_angle``
            (0.3: one side 30 % brighter, the other 30 % darker).
        gradient_angle: Direction of increasing light in the image [rad], 0 = towards +u.
        blur_sigma: Gaussian lens blur [px] (0 = sharp).
        front_occlusion: Fraction of the red marker's diameter hidden under a dark strip (0 none, 1 all).
        back_occlusion: Same for the blue marker.
        occluders: Extra discs drawn above the scene in tank coordinates.
        glare: Number of specular reflections (small white spots) at random places.
        red_bgr: Colour of the front marker (vary it to move its hue across 0/180).
        blue_bgr: Colour of the back marker.
    """

    noise_std: float = 2.0
    brightness: float = 1.0
    gradient: float = 0.0
    gradient_angle: float = 0.0
    blur_sigma: float = 0.0
    front_occlusion: float = 0.0
    back_occlusion: float = 0.0
    occluders: tuple[Occluder, ...] = ()
    glare: int = 0
    red_bgr: tuple[int, int, int] = RED_BGR
    blue_bgr: tuple[int, int, int] = BLUE_BGR

    def __post_init__(self) -> None:
        checks = (
            ("noise_std", self.noise_std >= 0),
            ("brightness", self.brightness > 0),
            ("gradient", 0 <= self.gradient < 1),
            ("blur_sigma", self.blur_sigma >= 0),
            ("front_occlusion", 0 <= self.front_occlusion <= 1),
            ("back_occlusion", 0 <= self.back_occlusion <= 1),
            ("glare", self.glare >= 0),
        )
        for name, ok in checks:
            value = getattr(self, name)
            if not np.isfinite(value) or not ok:
                raise ValueError(f"SceneConditions.{name} out of range: {value!r}")

    @classmethod
    def clean(cls) -> SceneConditions:
        """A noise-free, evenly lit, sharp frame."""
        return cls(noise_std=0.0)


@functools.lru_cache(maxsize=4)
def _noise_bank(size: int) -> np.ndarray:
    """``2 size`` unit Gaussian values (float32), drawn once per image size from a fixed seed."""
    return np.random.default_rng(0x5EED).standard_normal(2 * size, dtype=np.float32)


@functools.lru_cache(maxsize=8)
def _background(camera: CameraModel) -> np.ndarray:
    """Floor and walls at one sample per pixel (cached per camera)."""
    v, u = np.mgrid[0 : camera.height, 0 : camera.width].astype(float)
    tank = camera.pixel_to_tank(np.stack([u, v], axis=-1))
    image = np.empty((camera.height, camera.width, 3))
    image[:] = WALL_BGR
    image[_inside_tank(tank)] = FLOOR_BGR
    image.setflags(write=False)
    return image


def _inside_tank(tank: np.ndarray) -> np.ndarray:
    return (tank[..., 0] >= 0) & (tank[..., 0] <= TANK_LENGTH) & (tank[..., 1] >= 0) & (tank[..., 1] <= TANK_WIDTH)


def _paint(tank: np.ndarray, pose: tuple[float, float, float], conditions: SceneConditions) -> np.ndarray:
    """Colour of the scene at tank points ``(..., 2)`` (painter's algorithm, floor first)."""
    x, y, psi = pose
    colour = np.empty(tank.shape[:-1] + (3,))
    colour[:] = WALL_BGR
    colour[_inside_tank(tank)] = FLOOR_BGR
    cos, sin = np.cos(psi), np.sin(psi)
    dx, dy = tank[..., 0] - x, tank[..., 1] - y
    bx, by = cos * dx + sin * dy, -sin * dx + cos * dy  # body-frame coordinates
    colour[(bx / (BODY_LENGTH / 2)) ** 2 + (by / (BODY_WIDTH / 2)) ** 2 <= 1] = BODY_BGR
    for offset, bgr, hidden in (
        (FRONT_MARKER_OFFSET, conditions.red_bgr, conditions.front_occlusion),
        (BACK_MARKER_OFFSET, conditions.blue_bgr, conditions.back_occlusion),
    ):
        colour[(bx - offset) ** 2 + by**2 <= MARKER_RADIUS**2] = bgr
        if hidden > 0:  # a dark strip over the marker from its left side
            strip = (np.abs(bx - offset) <= 1.5 * MARKER_RADIUS) & (by >= MARKER_RADIUS * (1 - 2 * hidden))
            colour[strip & (by <= 2.5 * MARKER_RADIUS)] = OCCLUDER_BGR
    for occluder in conditions.occluders:
        colour[(tank[..., 0] - occluder.x) ** 2 + (tank[..., 1] - occluder.y) ** 2 <= occluder.radius**2] = (
            occluder.bgr
        )
    return colour


def _patch_boxes(
    pose: tuple[float, float, float], camera: CameraModel, conditions: SceneConditions
) -> list[tuple[int, int, int, int]]:
    """Pixel boxes (u0, v0, u1, v1), end exclusive, that contain a shape needing anti-aliasing."""
    x, y, psi = pose
    reach = BODY_LENGTH / 2 + 0.05  # covers the body and the occluding strips
    circles = [(x, y, reach)] + [(o.x, o.y, o.radius) for o in conditions.occluders]
    boxes = []
    for cx, cy, radius in circles:
        corners = np.array([[cx - radius, cy - radius], [cx + radius, cy - radius],
                            [cx + radius, cy + radius], [cx - radius, cy + radius]])
        pixels = camera.tank_to_pixel(corners)
        u0, v0 = np.floor(pixels.min(axis=0)).astype(int) - 1
        u1, v1 = np.ceil(pixels.max(axis=0)).astype(int) + 2
        u0, v0 = max(u0, 0), max(v0, 0)
        u1, v1 = min(u1, camera.width), min(v1, camera.height)
        if u1 > u0 and v1 > v0:
            boxes.append((int(u0), int(v0), int(u1), int(v1)))
    return boxes


def _render_patch(
    box: tuple[int, int, int, int], pose: tuple[float, float, float], camera: CameraModel, conditions: SceneConditions
) -> np.ndarray:
    """Anti-aliased colours of the pixels in ``box``: ``_SUPERSAMPLE^2`` samples where a shape's edge may pass.

    A pixel whose own centre and its eight neighbours' centres show one colour lies inside one region (the
    shapes are convex and several pixels across): its centre sample is its colour. Only the others (about a
    fifth of the patch) are supersampled; that keeps an in-process emulated camera at 30 frames/s.
    """
    u0, v0, u1, v1 = box
    height, width = v1 - v0, u1 - u0
    grid_u, grid_v = np.meshgrid(np.arange(u0 - 1, u1 + 1, dtype=float), np.arange(v0 - 1, v1 + 1, dtype=float))
    centres = _paint(camera.pixel_to_tank(np.stack([grid_u, grid_v], axis=-1)), pose, conditions)
    inner = centres[1:-1, 1:-1]
    uniform = np.ones((height, width), dtype=bool)
    for dv in (0, 1, 2):
        for du in (0, 1, 2):
            uniform &= np.all(centres[dv:dv + height, du:du + width] == inner, axis=-1)
    colour = inner.copy()
    rows, cols = np.nonzero(~uniform)
    if rows.size:
        s = _SUPERSAMPLE
        offsets = (np.arange(s) + 0.5) / s - 0.5
        sub_u = (cols + u0)[:, None, None] + offsets[None, None, :] + np.zeros((1, s, 1))
        sub_v = (rows + v0)[:, None, None] + offsets[None, :, None] + np.zeros((1, 1, s))
        samples = camera.pixel_to_tank(np.stack([sub_u, sub_v], axis=-1).reshape(-1, 2))
        colour[rows, cols] = _paint(samples, pose, conditions).reshape(rows.size, s * s, 3).mean(axis=1)
    return colour


def _lighting_gain(camera: CameraModel, conditions: SceneConditions) -> np.ndarray | float:
    if conditions.gradient == 0:
        return conditions.brightness
    v, u = np.mgrid[0 : camera.height, 0 : camera.width].astype(float)
    along = ((u - camera.width / 2) * np.cos(conditions.gradient_angle)
             + (v - camera.height / 2) * np.sin(conditions.gradient_angle))
    half_extent = 0.5 * np.hypot(camera.width, camera.height)
    return (conditions.brightness * (1 + conditions.gradient * along / half_extent))[..., None]


def _add_glare(image: np.ndarray, count: int, rng: np.random.Generator) -> None:
    height, width = image.shape[:2]
    for _ in range(count):
        centre = (int(rng.integers(0, width)), int(rng.integers(0, height)))
        axes = (int(rng.integers(2, 7)), int(rng.integers(1, 4)))
        angle = float(rng.uniform(0, 180))
        cv2.ellipse(image, centre, axes, angle, 0, 360, (255, 255, 255), -1, cv2.LINE_AA)


def render_frame(
    pose: tuple[float, float, float],
    camera: CameraModel,
    rng: np.random.Generator,
    conditions: SceneConditions | None = None,
) -> np.ndarray:
    """Render the overhead camera's view of the fish at ``pose``.

    Args:
        pose: (X [m], Y [m], psi [rad]) of the centre of mass in the tank frame.
        camera: The camera model.
        rng: Source of the sensor noise and glare positions (the only randomness).
        conditions: Imperfections; ``None`` means :class:`SceneConditions` defaults.

    Returns:
        (H, W, 3) uint8 BGR image.
    """
    if len(pose) != 3 or not np.all(np.isfinite(np.asarray(pose, dtype=float))):
        raise ValueError(f"pose must be three finite numbers (X, Y, psi), got {pose!r}")
    pose = tuple(float(p) for p in pose)
    conditions = SceneConditions() if conditions is None else conditions
    image = np.array(_background(camera), dtype=np.float32)
    for box in _patch_boxes(pose, camera, conditions):
        u0, v0, u1, v1 = box
        image[v0:v1, u0:u1] = _render_patch(box, pose, camera, conditions)
    # In place: the full-frame passes below are most of a frame's cost (it runs in a camera thread, 30 times a second)
    gain = _lighting_gain(camera, conditions)
    if isinstance(gain, np.ndarray):
        image = image * gain
    elif gain != 1.0:
        image *= gain
    if conditions.glare:
        _add_glare(image, conditions.glare, rng)
    if conditions.blur_sigma > 0:
        image = cv2.GaussianBlur(image, (0, 0), conditions.blur_sigma)
    if conditions.noise_std > 0:
        # A window of a noise bank drawn once, at an offset drawn from ``rng``: independent-looking sensor noise
        # per frame for a fraction of the cost of fresh normals (a camera thread renders 30 frames a second).
        bank = _noise_bank(image.size)
        start = int(rng.integers(0, image.size))
        image += bank[start:start + image.size].reshape(image.shape) * np.float32(conditions.noise_std)
    np.rint(image, out=image)
    np.clip(image, 0, 255, out=image)
    return image.astype(np.uint8)
