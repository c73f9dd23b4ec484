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

import cv2
import numpy as np

from pectoral_gym.hardware.vision.cameramodel import CameraModel, _apply_homography
from pectoral_gym.hardware.vision.scene_conditions import OCCLUDER_BGR, Occluder, SceneConditions
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

# Colours, BGR uint8 as OpenCV stores them (the markers' and the occluders': scene_conditions).
FLOOR_BGR = (205, 200, 190)  # light grey-blue tank floor
WALL_BGR = (70, 70, 75)  # dark tank walls / outside the swimming area
BODY_BGR = (80, 95, 105)  # dark grey-olive body

_SUPERSAMPLE = 4  # samples per pixel side for anti-aliased shapes


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


@functools.lru_cache(maxsize=4)
def _scaled_noise(size: int, noise_std: float) -> np.ndarray:
    """:func:`_noise_bank` times ``noise_std`` (float32, as each frame's window of it was scaled before)."""
    scaled = _noise_bank(size) * np.float32(noise_std)
    scaled.setflags(write=False)
    return scaled


@functools.lru_cache(maxsize=8)
def _pixel_grid(camera: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    """Tank points of the pixel centres from one pixel before to one after each image edge, and which are inside.

    Shapes ``(H + 2, W + 2, 2)`` and ``(H + 2, W + 2)``, cached per camera. A patch's grid is a slice of them: the
    matrix product gives a point the same bits in any array of points (tests/test_scene_patch.py).
    """
    grid_u, grid_v = np.meshgrid(np.arange(-1, camera.width + 1, dtype=float),
                                 np.arange(-1, camera.height + 1, dtype=float))
    tank = camera.pixel_to_tank(np.stack([grid_u, grid_v], axis=-1))
    inside = _inside_tank(tank)
    tank.setflags(write=False)
    inside.setflags(write=False)
    return tank, inside


def _inside_tank(tank: np.ndarray) -> np.ndarray:
    return (tank[..., 0] >= 0) & (tank[..., 0] <= TANK_LENGTH) & (tank[..., 1] >= 0) & (tank[..., 1] <= TANK_WIDTH)


@functools.lru_cache(maxsize=16)
def _palette(conditions: SceneConditions) -> tuple[np.ndarray, tuple[int, ...]]:
    """The scene's distinct colours ``(k, 3)`` and, per painting step of :func:`_labels`, its colour's index."""
    steps = [WALL_BGR, FLOOR_BGR, BODY_BGR, conditions.red_bgr, OCCLUDER_BGR, conditions.blue_bgr, OCCLUDER_BGR]
    steps += [occluder.bgr for occluder in conditions.occluders]
    colours = np.array(steps, dtype=float)
    distinct: list[int] = []  # first step of each colour (== as numpy compares: -0.0 is 0.0, NaN is no colour's)
    index = []
    for row in colours:
        same = [j for j, d in enumerate(distinct) if np.all(colours[d] == row)]
        if not same:
            distinct.append(len(index))
            same = [len(distinct) - 1]
        index.append(same[0])
    palette = colours[distinct]
    palette.setflags(write=False)
    return palette, tuple(index)


def _labels(tank: np.ndarray, pose: tuple[float, float, float], conditions: SceneConditions,
            index: tuple[int, ...], inside: np.ndarray | None = None) -> np.ndarray:
    """Palette index (uint8) of the scene's colour at tank points ``(..., 2)`` (painter's algorithm, floor first).

    One byte per point instead of a colour triple: the same tests in the same order as colours were painted.
    """
    x, y, psi = pose
    tx, ty = tank[..., 0], tank[..., 1]
    labels = np.full(tank.shape[:-1], index[0], dtype=np.uint8)
    labels[_inside_tank(tank) if inside is None else inside] = index[1]
    cos, sin = np.cos(psi), np.sin(psi)
    dx, dy = tx - x, ty - y
    bx, by = cos * dx + sin * dy, -sin * dx + cos * dy  # body-frame coordinates
    labels[(bx / (BODY_LENGTH / 2)) ** 2 + (by / (BODY_WIDTH / 2)) ** 2 <= 1] = index[2]
    for offset, step, hidden in (
        (FRONT_MARKER_OFFSET, 3, conditions.front_occlusion),
        (BACK_MARKER_OFFSET, 5, conditions.back_occlusion),
    ):
        labels[(bx - offset) ** 2 + by**2 <= MARKER_RADIUS**2] = index[step]
        if hidden > 0:  # a dark strip over the marker from its left side
            strip = (np.abs(bx - offset) <= 1.5 * MARKER_RADIUS) & (by >= MARKER_RADIUS * (1 - 2 * hidden))
            labels[strip & (by <= 2.5 * MARKER_RADIUS)] = index[step + 1]
    for step, occluder in enumerate(conditions.occluders, start=7):
        labels[(tx - occluder.x) ** 2 + (ty - occluder.y) ** 2 <= occluder.radius**2] = index[step]
    return labels


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
    """Whether every channel value is a whole number in [0, 255]."""
    return bool(np.all((colours >= 0) & (colours <= 255) & (colours == np.floor(colours))))


def _render_patch(
    box: tuple[int, int, int, int], pose: tuple[float, float, float], camera: CameraModel, conditions: SceneConditions
) -> np.ndarray:
    """Anti-aliased colours of the pixels in ``box``: ``_SUPERSAMPLE^2`` samples where a shape's edge may pass.

    A pixel whose own centre and its eight neighbours' centres show one colour lies inside one region (the
    shapes are convex and several pixels across): its centre sample is its colour. Only the others (about a
    tenth of the patch) are supersampled; that keeps an in-process emulated camera at 30 frames/s.
    """
    u0, v0, u1, v1 = box
    height, width = v1 - v0, u1 - u0
    palette, index = _palette(conditions)
    tank, inside = _pixel_grid(camera)
    centres = _labels(tank[v0:v1 + 2, u0:u1 + 2], pose, conditions, index, inside[v0:v1 + 2, u0:u1 + 2])
    inner = centres[1:-1, 1:-1]
    # The palette's colours are distinct, so equal labels are equal colours (a NaN colour equals none: not uniform)
    uniform = np.ones((height, width), dtype=bool) if np.all(palette == palette) else ~np.isnan(palette[inner]).any(-1)
    for dv in (0, 1, 2):
        for du in (0, 1, 2):
            if dv != 1 or du != 1:
                uniform &= centres[dv:dv + height, du:du + width] == inner
    colour = np.take(palette, inner, axis=0)  # palette[inner], without fancy indexing's overhead (3x slower)
    rows, cols = np.nonzero(~uniform)
    if rows.size:
        s = _SUPERSAMPLE
        offsets = (np.arange(s) + 0.5) / s - 0.5
        points = np.empty((rows.size, s * s, 2))  # sample (a, b) of a pixel at (u + offsets[b], v + offsets[a])
        points[..., 0] = (cols + u0)[:, None] + np.tile(offsets, s)
        points[..., 1] = (rows + v0)[:, None] + np.repeat(offsets, s)
        # pixel_to_tank's homography without its checks (the points are finite by construction)
        labels = _labels(_apply_homography(camera.inverse, points.reshape(-1, 2)), pose, conditions, index)
        if _whole(palette):
            # Sums of whole colours are exact in any order: counts @ palette is the samples' sum, bit for bit
            counts = np.bincount(np.arange(labels.size) // (s * s) * len(palette) + labels, minlength=rows.size
                                 * len(palette)).reshape(rows.size, len(palette))
            colour[rows, cols] = (counts.astype(float) @ palette) / (s * s)
        else:
            colour[rows, cols] = palette[labels.reshape(rows.size, s * s)].mean(axis=1)
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
    if (conditions.noise_std > 0 and conditions.brightness == 1.0 and conditions.gradient == 0
            and not conditions.glare and conditions.blur_sigma == 0):
        return _render_noisy(pose, camera, rng, conditions)
    return _render_general(pose, camera, rng, conditions)


def _render_general(
    pose: tuple[float, float, float], camera: CameraModel, rng: np.random.Generator, conditions: SceneConditions
) -> np.ndarray:
    """:func:`render_frame` under any conditions: a float image, the imperfections in turn, rounded at the end."""
    image = np.array(_background(camera), dtype=np.float32)
    for box in _patch_boxes(pose, camera, conditions):
        u0, v0, u1, v1 = box
        image[v0:v1, u0:u1] = _render_patch(box, pose, camera, conditions)
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
        image += _noise_window(image, rng, conditions.noise_std)
    np.rint(image, out=image)
    np.clip(image, 0, 255, out=image)
    return image.astype(np.uint8)


def _noise_window(image: np.ndarray, rng: np.random.Generator, noise_std: float) -> np.ndarray:
    """Sensor noise for ``image``: a window of a noise bank drawn once, at an offset drawn from ``rng``.

    Independent-looking sensor noise per frame for a fraction of the cost of fresh normals (a camera thread
    renders 30 frames a second).
    """
    start = int(rng.integers(0, image.size))
    return _scaled_noise(image.size, float(noise_std))[start:start + image.size].reshape(image.shape)


@functools.lru_cache(maxsize=2)
def _noisy_backgrounds(camera: CameraModel, noise_std: float) -> tuple[list[np.ndarray], list[list[np.ndarray]]]:
    """Each colour of the background plus the whole noise bank, rounded to uint8, and where that colour is.

    Returns ``(masks, tables)``: ``masks[k]`` (H, W, 3) uint8 marks the pixels of the background's colour ``k``;
    ``tables[k][p][j]`` is colour ``k``'s channel ``(j - p) % 3`` plus noise value ``j`` as a frame rounds it,
    so a frame whose noise window starts at ``start`` reads its background from ``tables[k][start % 3]``.
    """
    background = _background(camera)
    pixels = background.reshape(-1, 3)
    # one integer per colour (whole channel values 0-255), in the order of the rows (c0, c1, c2) sorted: a
    # 1-d unique instead of numpy's row-wise one, which sorts the pixels as structured rows (10x slower)
    codes = (pixels[:, 0].astype(np.int64) << 16) | (pixels[:, 1].astype(np.int64) << 8) | pixels[:, 2].astype(np.int64)
    _, first, inverse = np.unique(codes, return_index=True, return_inverse=True)
    colours = pixels[first]
    scaled = _scaled_noise(background.size, noise_std)
    masks, tables = [], []
    for k, colour in enumerate(colours):
        masks.append(np.repeat((inverse.reshape(background.shape[:2]) == k)[..., None], 3, axis=2).astype(np.uint8))
        repeated = np.tile(colour, scaled.size // 3 + 2)
        tables.append([cv2.add(repeated[-p % 3:-p % 3 + scaled.size], scaled, dtype=cv2.CV_8U) for p in range(3)])
    return masks, tables


def _render_noisy(
    pose: tuple[float, float, float], camera: CameraModel, rng: np.random.Generator, conditions: SceneConditions
) -> np.ndarray:
    """:func:`render_frame` under even, nominal light without glare or blur: the same pixels in fewer passes.

    The background's pixels plus noise are read from tables rounded once per camera (:func:`_noisy_backgrounds`),
    then each patch plus its noise is rounded and saturated to uint8 by OpenCV (half to even, as ``np.rint``).
    """
    background = _background(camera)
    size = background.size
    start = int(rng.integers(0, size))
    masks, tables = _noisy_backgrounds(camera, float(conditions.noise_std))
    window = slice(start, start + size)
    frame = tables[0][start % 3][window].reshape(background.shape).copy()
    for mask, table in zip(masks[1:], tables[1:], strict=True):
        cv2.copyTo(table[start % 3][window].reshape(background.shape), mask, frame)
    noise = _scaled_noise(size, float(conditions.noise_std))[window].reshape(background.shape)
    for box in _patch_boxes(pose, camera, conditions):
        u0, v0, u1, v1 = box
        patch = _render_patch(box, pose, camera, conditions).astype(np.float32)
        frame[v0:v1, u0:u1] = cv2.add(patch, noise[v0:v1, u0:u1], dtype=cv2.CV_8U)
    return frame
