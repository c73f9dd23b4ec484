"""Camera model and renderer: geometry by hand, marker placement, conditions, determinism."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.scene import (
    BACK_MARKER_OFFSET,
    FRONT_MARKER_OFFSET,
    MARKER_RADIUS,
    Occluder,
    SceneConditions,
    render_frame,
)
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH

CAMERA = CameraModel.default()


def test_default_camera_maps_tank_corners_inside_the_image_with_y_up():
    corners = CAMERA.tank_to_pixel([[0, 0], [TANK_LENGTH, 0], [TANK_LENGTH, TANK_WIDTH], [0, TANK_WIDTH]])
    assert np.all(corners >= 0) and np.all(corners[:, 0] < CAMERA.width) and np.all(corners[:, 1] < CAMERA.height)
    assert corners[1, 0] > corners[0, 0]  # X to the right
    assert corners[3, 1] < corners[0, 1]  # Y up (v decreases)
    # the tilt: the far wall (Y = W) looks shorter than the near one
    assert corners[2, 0] - corners[3, 0] < corners[1, 0] - corners[0, 0]


def test_homography_round_trip_and_scale():
    points = np.random.default_rng(0).uniform([0, 0], [TANK_LENGTH, TANK_WIDTH], (50, 2))
    np.testing.assert_allclose(CAMERA.pixel_to_tank(CAMERA.tank_to_pixel(points)), points, atol=1e-9)
    # near wall spans 596 px over 2.30 m
    assert CAMERA.pixels_per_metre((TANK_LENGTH / 2, 0.0)) == pytest.approx(596 / 2.30, rel=0.06)


def test_camera_rejects_bad_input():
    with pytest.raises(ValueError, match="3x3"):
        CameraModel(640, 360, np.eye(2))
    with pytest.raises(ValueError, match="singular"):
        CameraModel(640, 360, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="shape"):
        CAMERA.tank_to_pixel([1.0, 2.0, 3.0])


def test_save_load_round_trip(tmp_path):
    CAMERA.save(tmp_path / "c.json", note="x")
    loaded = CameraModel.load(tmp_path / "c.json")
    assert (loaded.width, loaded.height) == (CAMERA.width, CAMERA.height)
    np.testing.assert_allclose(loaded.homography, CAMERA.homography)
    (tmp_path / "bad.json").write_text('{"width": 3}')
    with pytest.raises(ValueError, match="calibration"):
        CameraModel.load(tmp_path / "bad.json")


def _marker_pixel(pose, offset):
    x, y, psi = pose
    return CAMERA.tank_to_pixel((x + offset * math.cos(psi), y + offset * math.sin(psi)))


@pytest.mark.parametrize("psi", [0.0, 1.0, -2.5])
def test_markers_drawn_where_the_pose_says(psi):
    pose = (1.2, 0.6, psi)
    image = render_frame(pose, CAMERA, np.random.default_rng(0), SceneConditions.clean())
    b, g, r = (image[..., i].astype(int) for i in range(3))
    for offset, mask in ((FRONT_MARKER_OFFSET, (r > 150) & (g < 100)), (BACK_MARKER_OFFSET, (b > 150) & (r < 80))):
        vs, us = np.nonzero(mask)
        np.testing.assert_allclose((us.mean(), vs.mean()), _marker_pixel(pose, offset), atol=0.5)
        expected_area = math.pi * (MARKER_RADIUS * CAMERA.pixels_per_metre(pose[:2])) ** 2
        assert mask.sum() == pytest.approx(expected_area, rel=0.3)


def test_rendering_is_deterministic_given_the_generator():
    conditions = SceneConditions(noise_std=5, glare=4, blur_sigma=0.7)
    first = render_frame((1, 0.5, 0.3), CAMERA, np.random.default_rng(7), conditions)
    second = render_frame((1, 0.5, 0.3), CAMERA, np.random.default_rng(7), conditions)
    third = render_frame((1, 0.5, 0.3), CAMERA, np.random.default_rng(8), conditions)
    assert first.shape == (CAMERA.height, CAMERA.width, 3) and first.dtype == np.uint8
    np.testing.assert_array_equal(first, second)
    assert np.any(first != third)


def test_noise_has_the_requested_spread():
    pose = (1.0, 0.5, 0.0)
    clean = render_frame(pose, CAMERA, np.random.default_rng(0), SceneConditions.clean()).astype(float)
    noisy = render_frame(pose, CAMERA, np.random.default_rng(0), SceneConditions(noise_std=4.0)).astype(float)
    assert np.std(noisy - clean) == pytest.approx(4.0, rel=0.05)


def test_brightness_and_gradient():
    pose = (1.0, 0.5, 0.0)
    rng = np.random.default_rng(0)
    base = render_frame(pose, CAMERA, rng, SceneConditions.clean()).astype(float)
    dim = render_frame(pose, CAMERA, rng, SceneConditions(noise_std=0, brightness=0.5)).astype(float)
    assert dim.mean() == pytest.approx(0.5 * base.mean(), rel=0.02)
    lit = render_frame(pose, CAMERA, rng, SceneConditions(noise_std=0, gradient=0.4)).astype(float)
    # light increases towards +u: right floor brighter than left floor
    assert lit[180, 560].mean() > 1.2 * lit[180, 80].mean()


def test_occlusion_hides_the_marker():
    pose = (1.0, 0.5, 0.4)
    image = render_frame(pose, CAMERA, np.random.default_rng(0), SceneConditions(noise_std=0, front_occlusion=1.0))
    r, g = image[..., 2].astype(int), image[..., 1].astype(int)
    assert not np.any((r > 150) & (g < 100))
    half = render_frame(pose, CAMERA, np.random.default_rng(0), SceneConditions(noise_std=0, front_occlusion=0.5))
    full = render_frame(pose, CAMERA, np.random.default_rng(0), SceneConditions(noise_std=0))
    red = [((im[..., 2] > 150) & (im[..., 1] < 100)).sum() for im in (half, full)]
    assert red[0] == pytest.approx(red[1] / 2, rel=0.35)


def test_occluder_and_blur():
    occluder = Occluder(0.5, 0.5, 0.05, (0, 255, 0))
    image = render_frame((1.5, 0.5, 0), CAMERA, np.random.default_rng(0),
                         SceneConditions(noise_std=0, occluders=(occluder,)))
    u, v = np.rint(CAMERA.tank_to_pixel((0.5, 0.5))).astype(int)
    assert tuple(image[v, u]) == (0, 255, 0)
    sharp = render_frame((1.5, 0.5, 0), CAMERA, np.random.default_rng(0), SceneConditions.clean())
    blurred = render_frame((1.5, 0.5, 0), CAMERA, np.random.default_rng(0), SceneConditions(noise_std=0, blur_sigma=2))
    assert cv2.Laplacian(blurred, cv2.CV_64F).var() < 0.5 * cv2.Laplacian(sharp, cv2.CV_64F).var()


def test_bad_pose_and_conditions():
    with pytest.raises(ValueError, match="pose"):
        render_frame((1.0, math.nan, 0.0), CAMERA, np.random.default_rng(0))
    with pytest.raises(ValueError, match="front_occlusion"):
        SceneConditions(front_occlusion=1.5)
