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

from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.scene_conditions import OCCLUDER_BGR, Occluder, SceneConditions
from pectoral_gym.hardware.vision.scene_kernels import (
    average_whole,
    copy_runs,
    paint_centres,
    paint_samples,
    sample_points,
)
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH, FishParams

__all__ = [
    "BACK_MARKER_OFFSET",
    "BODY_WIDTH",
    "FRONT_MARKER_OFFSET",
    "MARKER_RADIUS",
    "Occluder",
    "SceneConditions",
    "render_frame",
    "warm_up",
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
_SAMPLE_OFFSETS = (np.arange(_SUPERSAMPLE) + 0.5) / _SUPERSAMPLE - 0.5  # of the samples from a pixel's centre [px]


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
def _palette(conditions: SceneConditions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The scene's distinct colours ``(k, 3)``, per painting step its colour's index (uint8), and which are colours.

    The painting steps are :mod:`scene_kernels`'s (wall, floor, body, front marker, its strip, back marker, its
    strip, the occluders); a palette entry with a NaN channel is no colour (``False``: never uniform).
    """
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
    if len(distinct) > 256:  # labels are one byte
        raise ValueError(f"a scene of at most 256 distinct colours, got {len(distinct)}")
    palette = colours[distinct]
    opaque = ~np.isnan(palette).any(axis=1)
    labels = np.array(index, dtype=np.uint8)
    for array in (palette, labels, opaque):
        array.setflags(write=False)
    return palette, labels, opaque


# Farthest a point of the fish's shapes lies from its centre (body, marker discs, strips up to 2.5 marker radii to
# the side), with a margin of 1e-9 over the rounding of the body-frame rotation: a point farther is in none of them.
_REACH = (1 + 1e-9) * max(
    BODY_LENGTH / 2, BODY_WIDTH / 2,
    *(np.hypot(abs(offset) + 1.5 * MARKER_RADIUS, 2.5 * MARKER_RADIUS) for offset in (FRONT_MARKER_OFFSET,
                                                                                   BACK_MARKER_OFFSET)),
)


def _shapes(pose: tuple[float, float, float], conditions: SceneConditions) -> tuple[np.ndarray, np.ndarray]:
    """The painter's scalars for :mod:`scene_kernels` (``SHAPE_FIELDS``) and its occluders ``(k, 3)``.

    Each is computed as the numpy painter computed it (``cos``/``sin`` by numpy, squares by Python), so the
    kernel's tests are the painter's, bit for bit.
    """
    x, y, psi = pose
    front, back = conditions.front_occlusion, conditions.back_occlusion
    shapes = np.array([
        x, y, np.cos(psi), np.sin(psi), BODY_LENGTH / 2, BODY_WIDTH / 2, TANK_LENGTH, TANK_WIDTH,
        FRONT_MARKER_OFFSET, BACK_MARKER_OFFSET, MARKER_RADIUS**2, 1.5 * MARKER_RADIUS, 2.5 * MARKER_RADIUS,
        front, MARKER_RADIUS * (1 - 2 * front), back, MARKER_RADIUS * (1 - 2 * back), _REACH**2,
    ], dtype=float)
    occluders = np.array([(o.x, o.y, o.radius**2) for o in conditions.occluders], dtype=float).reshape(-1, 3)
    return shapes, occluders


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


@functools.lru_cache(maxsize=16)
def _whole_palette(conditions: SceneConditions) -> bool:
    """Whether the scene's palette is whole (:func:`_whole`), once per conditions."""
    return _whole(_palette(conditions)[0])


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
    palette, index, opaque = _palette(conditions)
    shapes, occluders = _shapes(pose, conditions)
    colour = np.empty((height, width, 3))
    edge = np.empty((height * width, 2), dtype=np.int64)
    count = paint_centres(_pixel_grid(camera)[0], v0, u0, height, width, shapes, occluders, index, opaque, palette,
                          colour, edge)
    if count:
        # pixel_to_tank's homography: its matrix product in numpy, with the same operands (a contiguous copy of
        # the strided one can take another BLAS path and round differently), its sums and quotients in the kernel
        inverse = camera.inverse
        homogeneous = sample_points(edge, count, u0, v0, _SAMPLE_OFFSETS) @ inverse[:, :2].T
        labels = paint_samples(homogeneous, inverse[:, 2], _SUPERSAMPLE**2, shapes, occluders, index)
        if _whole_palette(conditions):
            average_whole(labels, palette, edge, colour)  # sums of whole colours: exact in any order
        else:
            colour[edge[:count, 0], edge[:count, 1]] = palette[labels].mean(axis=1)
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


def warm_up() -> None:
    """Compile (or load from numba's cache) the renderer's kernels now, not at a camera thread's first frame.

    Renders one noisy frame of a small camera with the fish's edges in view: every kernel is called with the
    argument types of any frame (a fresh install compiles them in about 2 s of CPU).
    """
    camera = CameraModel.from_corners(64, 48, [[2, 46], [62, 46], [62, 2], [2, 2]])
    render_frame((TANK_LENGTH / 2, TANK_WIDTH / 2, 0.3), camera, np.random.default_rng(0), SceneConditions())


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
def _noisy_backgrounds(camera: CameraModel, noise_std: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """Each colour of the background plus the whole noise bank, rounded to uint8, and where that colour is.

    Returns ``(runs, tables)``: ``runs`` ``(r, 3)`` are the flat frame's byte ranges ``[first, end)`` of one
    background colour ``k`` each; ``tables[p][k, j]`` is colour ``k``'s channel ``(j - p) % 3`` plus noise value
    ``j`` as a frame rounds it, so a frame whose noise window starts at ``start`` reads its background from
    ``tables[start % 3]``.
    """
    background = _background(camera)
    pixels = background.reshape(-1, 3)
    # one integer per colour (whole channel values 0-255), in the order of the rows (c0, c1, c2) sorted: a
    # 1-d unique instead of numpy's row-wise one, which sorts the pixels as structured rows (10x slower)
    codes = (pixels[:, 0].astype(np.int64) << 16) | (pixels[:, 1].astype(np.int64) << 8) | pixels[:, 2].astype(np.int64)
    _, first, inverse = np.unique(codes, return_index=True, return_inverse=True)
    colours = pixels[first]
    inverse = inverse.reshape(-1)
    starts = np.flatnonzero(np.diff(inverse, prepend=-1))  # the first pixel of each run of one colour
    runs = np.stack([3 * starts, 3 * np.append(starts[1:], inverse.size), inverse[starts]], axis=1).astype(np.int64)
    scaled = _scaled_noise(background.size, noise_std)
    tables = [np.empty((len(colours), scaled.size), dtype=np.uint8) for _ in range(3)]
    for k, colour in enumerate(colours):
        repeated = np.tile(colour, scaled.size // 3 + 2)
        for p in range(3):
            tables[p][k] = cv2.add(repeated[-p % 3:-p % 3 + scaled.size], scaled, dtype=cv2.CV_8U).reshape(-1)
    runs.setflags(write=False)
    for table in tables:
        table.setflags(write=False)
    return runs, tables


def _render_noisy(
    pose: tuple[float, float, float], camera: CameraModel, rng: np.random.Generator, conditions: SceneConditions
) -> np.ndarray:
    """:func:`render_frame` under even, nominal light without glare or blur: the same pixels in fewer passes.

    The background's pixels plus noise are read from tables rounded once per camera (:func:`_noisy_backgrounds`),
    one pass over the frame by its runs of one colour; then each patch plus its noise is rounded and saturated to
    uint8 by OpenCV (half to even, as ``np.rint``).
    """
    background = _background(camera)
    size = background.size
    start = int(rng.integers(0, size))
    runs, tables = _noisy_backgrounds(camera, float(conditions.noise_std))
    frame = np.empty(background.shape, dtype=np.uint8)
    copy_runs(tables[start % 3], runs, start, frame.reshape(-1))
    noise = _scaled_noise(size, float(conditions.noise_std))[start:start + size].reshape(background.shape)
    for box in _patch_boxes(pose, camera, conditions):
        u0, v0, u1, v1 = box
        patch = _render_patch(box, pose, camera, conditions).astype(np.float32)
        window = frame[v0:v1, u0:u1]
        added = cv2.add(patch, noise[v0:v1, u0:u1], dst=window, dtype=cv2.CV_8U)
        if added is not window:  # OpenCV wrote into an array of its own instead of the frame's window
            window[...] = added
    return frame
