"""The tracker's search near the last sighting: the whole frame's pose, unless marker colours lie outside the window.

``MarkerTracker.track(frame, near=box)`` tests for marker pixels only in a window around ``box`` first. Held here to
two independent pipelines: the whole frame (``track(frame)``), and the whole frame with everything outside the
window painted a grey no marker test passes (what the window alone shows).
"""

from __future__ import annotations

import numpy as np
from test_tracker_crop import _frames

from pectoral_gym.hardware.vision.camera import Frame
from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.scene import SceneConditions, render_frame
from pectoral_gym.hardware.vision.tracker import NEAR_MARGIN, MarkerTracker, fish_box
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH

CAMERA = CameraModel.default()
TRACKER = MarkerTracker(CAMERA)


def _outside_blanked(image: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
    row0, row1, col0, col1 = box
    window = (max(row0 - NEAR_MARGIN, 0), row1 + NEAR_MARGIN, max(col0 - NEAR_MARGIN, 0), col1 + NEAR_MARGIN)
    blanked = np.full_like(image, 128)
    blanked[window[0]:window[1], window[2]:window[3]] = image[window[0]:window[1], window[2]:window[3]]
    return blanked


def test_near_a_moving_fish_the_pose_is_the_whole_frames():
    rng = np.random.default_rng(11)
    windowed = 0
    for k in range(80):
        # fish anywhere, also half out of view and at the image edges; the last sighting a few mm to 0.3 m away
        pose = (rng.uniform(-0.05, TANK_LENGTH + 0.05), rng.uniform(-0.05, TANK_WIDTH + 0.05), rng.uniform(-4, 4))
        step = rng.choice([0.005, 0.02, 0.3]) * rng.standard_normal(2)
        near = fish_box(CAMERA, (pose[0] + step[0], pose[1] + step[1]))
        conditions = SceneConditions(noise_std=float(rng.uniform(0, 6)))
        image = render_frame(pose, CAMERA, np.random.default_rng(k), conditions)
        whole = TRACKER.track(Frame(image, 1.0))
        result = TRACKER.track(Frame(image, 1.0), near=near)
        assert repr(result) == repr(whole), (k, pose, step)
        if near[0] < near[1] and near[2] < near[3]:
            window = (max(near[0] - NEAR_MARGIN, 0), near[1] + NEAR_MARGIN, max(near[2] - NEAR_MARGIN, 0),
                      near[3] + NEAR_MARGIN)
            windowed += whole.ok and TRACKER._near(image, window) is not None
    assert windowed > 20  # the window's own search was taken, not only the whole frame's


def test_with_distractors_the_pose_is_the_whole_frames_or_the_windows_alone():
    rng = np.random.default_rng(12)
    differ = same = 0
    for k, image in enumerate(_frames()):
        box = (int(rng.integers(0, CAMERA.height - 40)), 0, int(rng.integers(0, CAMERA.width - 40)), 0)
        box = (box[0], box[0] + int(rng.integers(20, 140)), box[2], box[2] + int(rng.integers(20, 140)))
        if k % 2:  # the box of the fish the frame shows, when it shows one
            found = TRACKER.track(Frame(image, 1.0))
            box = found.box if found.ok else box
        whole = TRACKER.track(Frame(image, 1.0))
        alone = TRACKER.track(Frame(_outside_blanked(image, box), 1.0))
        result = TRACKER.track(Frame(image, 1.0), near=box)
        if repr(result) == repr(whole):
            same += 1
        else:  # only a pose found in the window, the one the window alone gives
            assert result.ok and repr(result) == repr(alone), k
            differ += 1
    assert same > 30 and differ > 0


def test_a_fish_that_left_the_window_is_found_in_the_whole_frame():
    image = render_frame((1.5, 0.6, 0.2), CAMERA, np.random.default_rng(0))
    far_away = fish_box(CAMERA, (0.4, 0.3))
    result = TRACKER.track(Frame(image, 1.0), near=far_away)
    assert result.ok and abs(result.x - 1.5) < 0.003 and abs(result.y - 0.6) < 0.003
