"""The compiled renderer gives the numpy renderer's frames, byte for byte.

The numpy renderer it replaced is kept here as the reference: its painter (palette indices by numpy masks, in
painting order), its patch (uniform pixels by their centre, the others supersampled and summed by counting), its
noisy background (a copy of one table, OpenCV's masked copy of the others) and its frame. The frames are compared
over many seeded poses (in view, at the tank's walls, half out of view), conditions (marker strips, occluders of
every colour, a NaN colour, non-whole colours, noise levels, the general path's lighting, blur and glare) and two
cameras; the painter alone over points strewn densely around the fish's shapes and its reach.
"""

from __future__ import annotations

import functools
import math
import subprocess
import sys

import cv2
import numpy as np
import pytest
from test_scene_patch import _cases as _patch_cases

from pectoral_gym.hardware.vision import scene, scene_kernels
from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.scene import Occluder, SceneConditions, render_frame
from pectoral_gym.hardware.vision.scene_kernels import paint_samples
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH

CAMERAS = [CameraModel.default(), CameraModel.from_corners(320, 200, [[10, 190], [310, 185], [300, 12], [15, 8]])]
RED, BLUE = (40, 35, 205), (190, 90, 25)


def _reference_labels(tank, pose, conditions, index):
    """The numpy painter: palette index per tank point ``(..., 2)``, floor first, each later shape over it."""
    x, y, psi = pose
    tx, ty = tank[..., 0], tank[..., 1]
    labels = np.full(tank.shape[:-1], index[0], dtype=np.uint8)
    labels[scene._inside_tank(tank)] = index[1]
    cos, sin = np.cos(psi), np.sin(psi)
    dx, dy = tx - x, ty - y
    bx, by = cos * dx + sin * dy, -sin * dx + cos * dy
    labels[(bx / (scene.BODY_LENGTH / 2)) ** 2 + (by / (scene.BODY_WIDTH / 2)) ** 2 <= 1] = index[2]
    for offset, step, hidden in (
        (scene.FRONT_MARKER_OFFSET, 3, conditions.front_occlusion),
        (scene.BACK_MARKER_OFFSET, 5, conditions.back_occlusion),
    ):
        labels[(bx - offset) ** 2 + by**2 <= scene.MARKER_RADIUS**2] = index[step]
        if hidden > 0:
            strip = (np.abs(bx - offset) <= 1.5 * scene.MARKER_RADIUS) & (by >= scene.MARKER_RADIUS * (1 - 2 * hidden))
            labels[strip & (by <= 2.5 * scene.MARKER_RADIUS)] = index[step + 1]
    for step, occluder in enumerate(conditions.occluders, start=7):
        labels[(tx - occluder.x) ** 2 + (ty - occluder.y) ** 2 <= occluder.radius**2] = index[step]
    return labels


def _reference_patch(box, pose, camera, conditions):
    """The numpy patch: the cached grid's slice labelled, uniform pixels by their centre, the others supersampled."""
    u0, v0, u1, v1 = box
    height, width = v1 - v0, u1 - u0
    palette, index, _ = scene._palette(conditions)
    tank, _ = scene._pixel_grid(camera)
    centres = _reference_labels(tank[v0:v1 + 2, u0:u1 + 2], pose, conditions, index)
    inner = centres[1:-1, 1:-1]
    uniform = np.ones((height, width), dtype=bool) if np.all(palette == palette) else ~np.isnan(palette[inner]).any(-1)
    for dv in (0, 1, 2):
        for du in (0, 1, 2):
            if dv != 1 or du != 1:
                uniform &= centres[dv:dv + height, du:du + width] == inner
    colour = np.take(palette, inner, axis=0)
    rows, cols = np.nonzero(~uniform)
    if rows.size:
        s = scene._SUPERSAMPLE
        offsets = (np.arange(s) + 0.5) / s - 0.5
        points = np.empty((rows.size, s * s, 2))
        points[..., 0] = (cols + u0)[:, None] + np.tile(offsets, s)
        points[..., 1] = (rows + v0)[:, None] + np.repeat(offsets, s)
        labels = _reference_labels(camera.pixel_to_tank(points.reshape(-1, 2)), pose, conditions, index)
        if scene._whole(palette):
            counts = np.bincount(np.arange(labels.size) // (s * s) * len(palette) + labels, minlength=rows.size
                                 * len(palette)).reshape(rows.size, len(palette))
            colour[rows, cols] = (counts.astype(float) @ palette) / (s * s)
        else:
            colour[rows, cols] = palette[labels.reshape(rows.size, s * s)].mean(axis=1)
    return colour


@functools.lru_cache(maxsize=4)
def _reference_tables(camera, noise_std):
    """The numpy renderer's noisy backgrounds: per colour a mask of its pixels and its three phases' tables."""
    background = scene._background(camera)
    pixels = background.reshape(-1, 3)
    codes = (pixels[:, 0].astype(np.int64) << 16) | (pixels[:, 1].astype(np.int64) << 8) | pixels[:, 2].astype(np.int64)
    _, first, inverse = np.unique(codes, return_index=True, return_inverse=True)
    scaled = scene._scaled_noise(background.size, noise_std)
    masks, tables = [], []
    for k, colour in enumerate(pixels[first]):
        masks.append(np.repeat((inverse.reshape(background.shape[:2]) == k)[..., None], 3, axis=2).astype(np.uint8))
        repeated = np.tile(colour, scaled.size // 3 + 2)
        tables.append([cv2.add(repeated[-p % 3:-p % 3 + scaled.size], scaled, dtype=cv2.CV_8U) for p in range(3)])
    return masks, tables


def _reference_frame(pose, camera, rng, conditions):
    """The numpy renderer's frame (its noisy path: one table copied, the other colours by masked copies)."""
    if not (conditions.noise_std > 0 and conditions.brightness == 1.0 and conditions.gradient == 0
            and not conditions.glare and conditions.blur_sigma == 0):
        image = np.array(scene._background(camera), dtype=np.float32)
        for box in scene._patch_boxes(pose, camera, conditions):
            image[box[1]:box[3], box[0]:box[2]] = _reference_patch(box, pose, camera, conditions)
        gain = scene._lighting_gain(camera, conditions)
        if isinstance(gain, np.ndarray):
            image = image * gain
        elif gain != 1.0:
            image *= gain
        if conditions.glare:
            scene._add_glare(image, conditions.glare, rng)
        if conditions.blur_sigma > 0:
            image = cv2.GaussianBlur(image, (0, 0), conditions.blur_sigma)
        if conditions.noise_std > 0:
            image += scene._noise_window(image, rng, conditions.noise_std)
        return np.clip(np.rint(image), 0, 255).astype(np.uint8)
    background = scene._background(camera)
    size, start = background.size, int(rng.integers(0, background.size))
    masks, tables = _reference_tables(camera, float(conditions.noise_std))
    window = slice(start, start + size)
    frame = tables[0][start % 3][window].reshape(background.shape).copy()
    for mask, table in zip(masks[1:], tables[1:], strict=True):
        cv2.copyTo(table[start % 3][window].reshape(background.shape), mask, frame)
    scaled = scene._scaled_noise(size, float(conditions.noise_std))
    noise = scaled[window].reshape(background.shape)
    for box in scene._patch_boxes(pose, camera, conditions):
        u0, v0, u1, v1 = box
        patch = _reference_patch(box, pose, camera, conditions).astype(np.float32)
        frame[v0:v1, u0:u1] = cv2.add(patch, noise[v0:v1, u0:u1], dtype=cv2.CV_8U)
    return frame


# the patch test's cases, with the sensor noise drawn too and the front marker fully hidden among them
_cases = functools.partial(_patch_cases, noise_levels=[2.0, 0.0, 0.7, 40.0], front_occlusions=[0.0, 0.3, 1.0])


def test_frames_are_the_numpy_renderers_byte_for_byte():
    for k, (camera, pose, conditions) in enumerate(_cases(400, seed=11)):
        ours = render_frame(pose, camera, np.random.default_rng(k), conditions)
        ref = _reference_frame(pose, camera, np.random.default_rng(k), conditions)
        assert ours.dtype == np.uint8 and ours.tobytes() == ref.tobytes(), (pose, conditions)


@pytest.mark.parametrize("imperfection", [
    {"brightness": 0.7}, {"gradient": 0.3, "gradient_angle": 0.4}, {"blur_sigma": 1.2}, {"glare": 3},
    {"brightness": 1.2, "blur_sigma": 0.6, "glare": 2, "noise_std": 5.0},
])
def test_frames_of_the_general_path_are_the_numpy_renderers(imperfection):
    for k, (camera, pose, conditions) in enumerate(_cases(12, seed=13)):
        conditions = SceneConditions(**{"noise_std": conditions.noise_std, "occluders": conditions.occluders,
                                        "front_occlusion": conditions.front_occlusion, **imperfection})
        ours = render_frame(pose, camera, np.random.default_rng(k), conditions)
        ref = _reference_frame(pose, camera, np.random.default_rng(k), conditions)
        assert ours.tobytes() == ref.tobytes(), (pose, conditions)


def test_a_nan_colour_gives_the_numpy_patch():
    conditions = SceneConditions(occluders=(Occluder(1.0, 0.5, 0.05, (math.nan, 10, 10)),))
    for box in scene._patch_boxes((1.0, 0.5, 0.3), CAMERAS[0], conditions):
        ours = scene._render_patch(box, (1.0, 0.5, 0.3), CAMERAS[0], conditions)
        assert np.array_equal(ours, _reference_patch(box, (1.0, 0.5, 0.3), CAMERAS[0], conditions), equal_nan=True)


def _unit_offset():
    """(0, 0, 1) as the renderer passes a homography's third column: a strided read-only view (one kernel type)."""
    matrix = np.zeros((3, 3))
    matrix[2, 2] = 1.0
    matrix.setflags(write=False)
    return matrix[:, 2]


_UNIT_OFFSET = _unit_offset()


def test_the_painter_is_the_numpy_painter_at_points_around_every_shape():
    """Points strewn around the fish, densest at its reach (where the kernel stops testing the fish's shapes)."""
    rng = np.random.default_rng(17)
    for k in range(40):
        pose = (float(rng.uniform(0, TANK_LENGTH)), float(rng.uniform(0, TANK_WIDTH)), float(rng.uniform(-4, 4)))
        conditions = SceneConditions(
            front_occlusion=float(rng.choice([0.0, 0.25, 1.0])), back_occlusion=float(rng.choice([0.0, 0.5])),
            occluders=(Occluder(pose[0] + 0.03, pose[1], 0.02, RED),) if k % 2 else (),
        )
        _, index, _ = scene._palette(conditions)
        angle = rng.uniform(0, 2 * np.pi, 200_000)
        radius = np.concatenate([rng.uniform(0, 0.12, 100_000), scene._REACH * (1 + rng.uniform(-1e-6, 1e-6, 100_000))])
        tank = np.stack([pose[0] + radius * np.cos(angle), pose[1] + radius * np.sin(angle)], axis=-1)
        homogeneous = np.concatenate([tank, np.zeros((len(tank), 1))], axis=1)  # (tx + 0) / (0 + 1) is tx
        ours = paint_samples(homogeneous, _UNIT_OFFSET, 1, *scene._shapes(pose, conditions), index)
        ref = _reference_labels(tank, pose, conditions, index)
        assert np.array_equal(ours[:, 0], ref)
        assert len(np.unique(ref)) >= 3  # the points reach floor, body and a marker at least


def test_the_reach_holds_every_shape_of_the_fish():
    """Beyond the reach the numpy painter paints no fish: points just outside it in every direction and pose."""
    rng = np.random.default_rng(19)
    conditions = SceneConditions(front_occlusion=1.0, back_occlusion=1.0)
    _, index, _ = scene._palette(conditions)
    for psi in rng.uniform(-4, 4, 20):
        angle = np.linspace(0, 2 * np.pi, 100_000)
        radius = scene._REACH / (1 + 1e-9) * (1 + 1e-12)
        tank = np.stack([0.5 + radius * np.cos(angle), 0.4 + radius * np.sin(angle)], axis=-1)
        assert np.all(_reference_labels(tank, (0.5, 0.4, psi), conditions, index) == index[1])


KERNELS = ("paint_centres", "sample_points", "paint_samples", "average_whole", "copy_runs")


def test_warm_up_alone_compiles_every_kernel():
    """In a fresh process (numba's cache may hold them: loading them counts), ``warm_up`` and nothing else."""
    code = ("from pectoral_gym.hardware.vision import scene, scene_kernels as k; scene.warm_up(); "
            f"print([len(getattr(k, name).dispatcher.signatures) for name in {KERNELS!r}])")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    assert result.stdout.split("\n")[-2] == str([1] * len(KERNELS))


def test_frames_after_warm_up_compile_nothing_more():
    """Frames of other cameras and conditions after ``warm_up`` reuse its kernels (one signature each)."""
    scene.warm_up()
    for camera, pose, conditions in _cases(6, seed=23):
        render_frame(pose, camera, np.random.default_rng(0), conditions)
    for name in KERNELS:
        assert len(getattr(scene_kernels, name).dispatcher.signatures) == 1, name
