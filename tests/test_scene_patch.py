"""The renderer's faster paths give the pixels of the straightforward ones, bit for bit.

* patches are painted as palette indices (one byte per sample) and supersampled pixels summed by counting:
  held to the colour painter the renderer used before (kept here as the reference);
* a patch's grid of tank points is a slice of one cached grid per camera: held to the points computed for the
  patch alone;
* frames under even nominal light without glare or blur are rounded to uint8 by OpenCV in one pass: held to
  the general path (float image, ``np.rint``, clip).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pectoral_gym.hardware.vision import scene
from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.scene import Occluder, SceneConditions, render_frame
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH

CAMERAS = [CameraModel.default(), CameraModel.from_corners(320, 200, [[10, 190], [310, 185], [300, 12], [15, 8]])]


def _reference_paint(tank, pose, conditions):
    """The colour painter (float64 BGR per point) the renderer used before palette indices."""
    x, y, psi = pose
    colour = np.empty(tank.shape[:-1] + (3,))
    colour[:] = scene.WALL_BGR
    colour[scene._inside_tank(tank)] = scene.FLOOR_BGR
    cos, sin = np.cos(psi), np.sin(psi)
    dx, dy = tank[..., 0] - x, tank[..., 1] - y
    bx, by = cos * dx + sin * dy, -sin * dx + cos * dy
    colour[(bx / (scene.BODY_LENGTH / 2)) ** 2 + (by / (scene.BODY_WIDTH / 2)) ** 2 <= 1] = scene.BODY_BGR
    for offset, bgr, hidden in (
        (scene.FRONT_MARKER_OFFSET, conditions.red_bgr, conditions.front_occlusion),
        (scene.BACK_MARKER_OFFSET, conditions.blue_bgr, conditions.back_occlusion),
    ):
        colour[(bx - offset) ** 2 + by**2 <= scene.MARKER_RADIUS**2] = bgr
        if hidden > 0:
            strip = (np.abs(bx - offset) <= 1.5 * scene.MARKER_RADIUS) & (by >= scene.MARKER_RADIUS * (1 - 2 * hidden))
            colour[strip & (by <= 2.5 * scene.MARKER_RADIUS)] = scene.OCCLUDER_BGR
    for occluder in conditions.occluders:
        colour[(tank[..., 0] - occluder.x) ** 2 + (tank[..., 1] - occluder.y) ** 2 <= occluder.radius**2] = (
            occluder.bgr
        )
    return colour


def _reference_patch(box, pose, camera, conditions):
    """The colour-based patch renderer used before (grid of the patch alone, colours compared, samples averaged)."""
    u0, v0, u1, v1 = box
    height, width = v1 - v0, u1 - u0
    grid_u, grid_v = np.meshgrid(np.arange(u0 - 1, u1 + 1, dtype=float), np.arange(v0 - 1, v1 + 1, dtype=float))
    centres = _reference_paint(camera.pixel_to_tank(np.stack([grid_u, grid_v], axis=-1)), pose, conditions)
    inner = centres[1:-1, 1:-1]
    keys = centres @ np.array([1.0, 256.0, 65536.0]) if scene._whole(centres) else None
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
        s = scene._SUPERSAMPLE
        offsets = (np.arange(s) + 0.5) / s - 0.5
        sub_u = (cols + u0)[:, None, None] + offsets[None, None, :] + np.zeros((1, s, 1))
        sub_v = (rows + v0)[:, None, None] + offsets[None, :, None] + np.zeros((1, 1, s))
        samples = camera.pixel_to_tank(np.stack([sub_u, sub_v], axis=-1).reshape(-1, 2))
        colour[rows, cols] = _reference_paint(samples, pose, conditions).reshape(rows.size, s * s, 3).mean(axis=1)
    return colour


def _cases(n, seed, noise_levels=None, front_occlusions=(0.0, 0.3)):
    """``n`` seeded ``(camera, pose, conditions)``: poses in view, at the walls and half out, occluders of every
    colour, marker strips, non-whole colours; the sensor noise drawn from ``noise_levels`` (None: the default)."""
    rng = np.random.default_rng(seed)
    red, blue = (40, 35, 205), (190, 90, 25)
    for k in range(n):
        pose = (rng.uniform(-0.1, TANK_LENGTH + 0.1), rng.uniform(-0.1, TANK_WIDTH + 0.1), rng.uniform(-4, 4))
        occluders = tuple(
            Occluder(pose[0] + rng.uniform(-0.2, 0.2), pose[1] + rng.uniform(-0.2, 0.2), rng.uniform(0.005, 0.05),
                     (red, blue, scene.OCCLUDER_BGR, scene.BODY_BGR, (10.5, 20.25, 30.0))[rng.integers(5)])
            for _ in range(rng.integers(0, 3))
        )
        noise = {} if noise_levels is None else {"noise_std": float(rng.choice(noise_levels))}
        conditions = SceneConditions(
            **noise, front_occlusion=float(rng.choice(front_occlusions)), back_occlusion=float(rng.choice([0.0, 0.6])),
            occluders=occluders, red_bgr=((40, 35, 205), (60, 40, 200.5), (190, 90, 25))[k % 3],
        )
        yield CAMERAS[k % 2], pose, conditions


def test_palette_patches_are_the_colour_painters_bit_for_bit():
    boxes = 0
    for camera, pose, conditions in _cases(150, seed=3):
        for box in scene._patch_boxes(pose, camera, conditions):
            ours = scene._render_patch(box, pose, camera, conditions)
            assert ours.dtype == np.float64 and np.array_equal(ours, _reference_patch(box, pose, camera, conditions))
            boxes += 1
    assert boxes > 150


def test_a_nan_colour_is_never_uniform_as_before():
    conditions = SceneConditions(occluders=(Occluder(1.0, 0.5, 0.05, (math.nan, 10, 10)),))
    camera = CAMERAS[0]
    for box in scene._patch_boxes((1.0, 0.5, 0.3), camera, conditions):
        ours = scene._render_patch(box, (1.0, 0.5, 0.3), camera, conditions)
        ref = _reference_patch(box, (1.0, 0.5, 0.3), camera, conditions)
        assert np.array_equal(ours, ref, equal_nan=True)


def test_patch_grids_sliced_from_the_cached_grid_are_the_patch_alone_points():
    rng = np.random.default_rng(0)
    for camera in CAMERAS:
        tank, inside = scene._pixel_grid(camera)
        for _ in range(500):
            u0, v0 = int(rng.integers(0, camera.width)), int(rng.integers(0, camera.height))
            u1 = int(rng.integers(u0 + 1, min(camera.width, u0 + 120) + 1))
            v1 = int(rng.integers(v0 + 1, min(camera.height, v0 + 120) + 1))
            grid_u, grid_v = np.meshgrid(np.arange(u0 - 1, u1 + 1, dtype=float),
                                         np.arange(v0 - 1, v1 + 1, dtype=float))
            alone = camera.pixel_to_tank(np.stack([grid_u, grid_v], axis=-1))
            assert np.array_equal(alone, tank[v0:v1 + 2, u0:u1 + 2])
            assert np.array_equal(scene._inside_tank(alone), inside[v0:v1 + 2, u0:u1 + 2])


@pytest.mark.parametrize("noise_std", [2.0, 0.7, 40.0])
def test_one_pass_rounding_gives_the_general_paths_frames(noise_std):
    for camera, pose, conditions in _cases(40, seed=5):
        conditions = SceneConditions(noise_std=noise_std, occluders=conditions.occluders,
                                     front_occlusion=conditions.front_occlusion)
        seed = int(1000 * pose[0]) % 97
        fast = render_frame(pose, camera, np.random.default_rng(seed), conditions)
        general = scene._render_general(pose, camera, np.random.default_rng(seed), conditions)
        assert fast.dtype == np.uint8 and np.array_equal(fast, general)
