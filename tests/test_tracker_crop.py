"""The tracker segments only the box of the frame that can hold marker pixels: the result is the whole frame's.

``MarkerTracker.track`` converts to HSV, thresholds and cleans only a box around the pixels that pass a cheap
necessary test of saturation (``MarkerTracker._candidates``). These tests hold it to the whole-frame pipeline
(conversion, thresholds, cleanup and blobs of the full image), blob for blob, on frames with distractors anywhere,
and check the necessary test on every 8-bit colour.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from pectoral_gym.hardware.vision.camera import Frame
from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.scene import Occluder, SceneConditions, render_frame
from pectoral_gym.hardware.vision.tracker import MarkerTracker, TrackerConfig
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH

CAMERA = CameraModel.default()


def _whole_frame_blobs(tracker: MarkerTracker, image: np.ndarray) -> dict:
    """The blobs of the whole frame, segmented without a crop (the pipeline before the crop)."""
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    cfg = tracker.config
    return {"red": tracker._blobs(tracker._mask(hsv, cfg.red_hue_bands)),
            "blue": tracker._blobs(tracker._mask(hsv, cfg.blue_hue_bands))}


def _all_colours() -> np.ndarray:
    codes = np.arange(1 << 24, dtype=np.uint32)
    channels = [codes & 255, (codes >> 8) & 255, codes >> 16]
    return np.stack(channels, axis=-1).astype(np.uint8).reshape(4096, 4096, 3)


@pytest.mark.parametrize(("min_saturation", "min_value"), [(110, 30), (86, 0), (86, 30), (200, 100)])
def test_candidate_test_passes_every_colour_a_mask_can_pass(min_saturation, min_value):
    image = _all_colours()
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    can_pass = (hsv[..., 1] >= min_saturation) & (hsv[..., 2] >= min_value)
    tracker = MarkerTracker(CAMERA, TrackerConfig(min_saturation=min_saturation, min_value=min_value))
    # Every colour at once is a full frame of candidates; one colour at a time is what the box is made of.
    assert tracker._candidates(image) == (0, 4096, 0, 4096)
    blue, green, red = cv2.split(image)
    high = cv2.max(cv2.max(blue, green), red)
    spread = cv2.subtract(high, cv2.min(cv2.min(blue, green), red))
    spread = cv2.add(cv2.add(spread, spread), spread)
    candidate = cv2.compare(spread, cv2.max(high, float(min_value)), cv2.CMP_GE) > 0
    assert not np.any(can_pass & ~candidate)
    if min_saturation == 110:  # the default: the floor, walls, body and grey glare are no candidates
        for bgr in ((205, 200, 190), (70, 70, 75), (80, 95, 105), (255, 255, 255), (45, 45, 50)):
            assert not candidate.reshape(-1)[bgr[0] + 256 * bgr[1] + 65536 * bgr[2]]


def test_below_the_proven_saturation_the_whole_frame_is_segmented():
    tracker = MarkerTracker(CAMERA, TrackerConfig(min_saturation=85))
    image = np.zeros((CAMERA.height, CAMERA.width, 3), np.uint8)
    assert tracker._candidates(image) == (0, CAMERA.height, 0, CAMERA.width)


def _frames():
    """Rendered frames with marker-coloured distractors anywhere (also at the image edges), and noise images."""
    rng = np.random.default_rng(7)
    red, blue = (40, 35, 205), (190, 90, 25)
    for k in range(60):
        pose = (rng.uniform(-0.1, TANK_LENGTH + 0.1), rng.uniform(-0.1, TANK_WIDTH + 0.1), rng.uniform(-4, 4))
        occluders = tuple(
            Occluder(rng.uniform(-0.05, TANK_LENGTH + 0.05), rng.uniform(-0.05, TANK_WIDTH + 0.05),
                     rng.uniform(0.005, 0.04), (red, blue, (45, 45, 50))[rng.integers(3)])
            for _ in range(rng.integers(0, 4))
        )
        conditions = SceneConditions(noise_std=float(rng.uniform(0, 6)), occluders=occluders,
                                     glare=int(rng.integers(0, 3)), blur_sigma=float(rng.choice([0.0, 0.8])))
        yield render_frame(pose, CAMERA, np.random.default_rng(k), conditions)
    for k in range(4):  # saturated pixels everywhere, and a sprinkle of them on a dark frame
        yield np.random.default_rng(k).integers(0, 256, (CAMERA.height, CAMERA.width, 3), dtype=np.uint8)
        sparse = np.full((CAMERA.height, CAMERA.width, 3), 20, np.uint8)
        rows, cols = rng.integers(0, CAMERA.height, 30), rng.integers(0, CAMERA.width, 30)
        sparse[rows, cols] = red if k % 2 else blue
        sparse[rows[:5], 0] = blue
        yield sparse


@pytest.mark.parametrize("config", [TrackerConfig(), TrackerConfig(kernel_size=5, min_saturation=90)],
                         ids=["default", "wide-kernel"])
def test_cropped_segmentation_finds_the_blobs_of_the_whole_frame(config):
    tracker = MarkerTracker(CAMERA, config)
    lost = found = cropped = 0
    for image in _frames():
        framed = np.pad(image, ((1, 2), (3, 4), (0, 0)))
        for view in (image, framed[1:-2, 3:-4]):  # also a frame that is a view into a larger buffer
            result = tracker.track(Frame(view, 1.0))
            assert repr(tracker.last_blobs) == repr(_whole_frame_blobs(tracker, np.ascontiguousarray(view)))
            found, lost = found + result.ok, lost + (not result.ok)
            box = tracker._candidates(view)
            cropped += box is not None and (box[1] - box[0]) * (box[3] - box[2]) < view.shape[0] * view.shape[1] / 4
    assert found > 10 and lost > 10 and cropped > 40  # both outcomes, mostly on crops, were compared


def test_frame_without_candidates_is_lost_as_before():
    image = render_frame((-1.0, -1.0, 0.0), CAMERA, np.random.default_rng(0))  # no fish in view
    result = MarkerTracker(CAMERA).track(Frame(image, 2.0))
    assert not result.ok and result.reason == "red (front) marker not found" and math.isnan(result.x)
