"""A renderer of what the overhead camera sees of the tank and the fish.

The tank frame is the simulation's: origin at one corner of the ``TANK_LENGTH x TANK_WIDTH`` swimming area,
X along the length, Y along the width, heading ``psi`` from +X towards +Y, all in metres and radians.
The camera is a :class:`~pectoral_gym.hardware.vision.cameramodel.CameraModel` (a plane-to-image homography, tank
metres -> pixels, of the marker plane); pixel coordinates follow OpenCV: ``u`` to the right, ``v`` down, pixel
centres at integer coordinates.

The fish is drawn as an ellipse of ``FishParams().body_length`` by :data:`BODY_WIDTH` with a red disc marker of
radius :data:`MARKER_RADIUS` at :data:`FRONT_MARKER_OFFSET` and a blue one at :data:`BACK_MARKER_OFFSET` along the
body x axis. Shapes are anti-aliased by supersampling so marker centroids are sub-pixel accurate, then the
imperfections of :class:`SceneConditions` (lighting, occlusion, blur, noise, glare) are applied. Rendering is
deterministic given the generator.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH, FishParams

__all__ = [
    "BACK_MARKER_OFFSET",
    "BODY_WIDTH",
    "FRONT_MARKER_OFFSET",
    "MARKER_RADIUS",
    "Occluder",
    "SceneConditions",
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
    """Floor and walls at one sample per pixel (cached per camera; float32 holds the whole colour values exactly)."""
    v, u = np.mgrid[0 : camera.height, 0 : camera.width].astype(float)
    tank = camera.pixel_to_tank(np.stack([u, v], axis=-1))
    image = np.empty((camera.height, camera.width, 3), dtype=np.float32)
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


def _whole(colours: np.ndarray) -> bool:
    """Whether every channel value is a whole number in [0, 255] (then ``B + 256 G + 65536 R`` names the colour)."""
    return bool(np.all((colours >= 0) & (colours <= 255) & (colours == np.floor(colours))))


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
    # Colours are whole BGR triples, so one number per colour compares them all at once (exactly)
    keys = centres @ np.array([1.0, 256.0, 65536.0]) if _whole(centres) else None
    uniform = np.ones((height, width), dtype=bool)
    for dv in (0, 1, 2):
        for du in (0, 1, 2):
            if keys is not None:
                uniform &= keys[dv:dv + height, du:du + width] == keys[1:-1, 1:-1]
            else:
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
