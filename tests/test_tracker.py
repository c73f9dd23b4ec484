"""Marker tracker on rendered frames: accuracy, lost markers, hue wrap, distractors, lighting."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pectoral_gym.hardware.vision.camera import Frame
from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.scene import FRONT_MARKER_OFFSET, Occluder, SceneConditions, render_frame
from pectoral_gym.hardware.vision.tracker import MarkerTracker, TrackerConfig
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH

CAMERA = CameraModel.default()
TRACKER = MarkerTracker(CAMERA)
POSITION_TOL = 0.005  # m
HEADING_TOL = math.radians(2.0)
# A marker with up to ~30 % of its diameter hidden can pass the size/shape gates; its centroid then moves by up
# to ~2 mm (measured: max 2.0 deg over 300 poses). "Never wrong" for such frames: within 5 mm and 2.5 deg.
HEADING_TOL_PARTLY_HIDDEN = math.radians(2.5)


def _poses(n, seed):
    rng = np.random.default_rng(seed)
    margin = 0.12
    xs = rng.uniform(margin, TANK_LENGTH - margin, n)
    ys = rng.uniform(margin, TANK_WIDTH - margin, n)
    return list(zip(xs, ys, rng.uniform(-math.pi, math.pi, n), strict=True))


def _track(pose, conditions, seed=0, timestamp=1.5):
    image = render_frame(pose, CAMERA, np.random.default_rng(seed), conditions)
    return TRACKER.track(Frame(image, timestamp))


def _errors(result, pose):
    heading = abs((result.psi - pose[2] + math.pi) % (2 * math.pi) - math.pi)
    return math.hypot(result.x - pose[0], result.y - pose[1]), heading


@pytest.mark.parametrize("conditions", [SceneConditions.clean(), SceneConditions()], ids=["clean", "default"])
def test_pose_within_5mm_and_2deg_over_many_random_poses(conditions):
    for pose in _poses(40, seed=1):
        result = _track(pose, conditions)
        assert result.ok, (pose, result.reason)
        position, heading = _errors(result, pose)
        assert position < POSITION_TOL and heading < HEADING_TOL, (pose, position, math.degrees(heading))
        assert 0 < result.confidence <= 1 and result.timestamp == 1.5 and result.reason == ""


def test_heading_points_from_back_to_front():
    # swimming along +X: psi = 0, the red marker has the larger X
    result = _track((1.0, 0.5, 0.0), SceneConditions.clean())
    assert result.psi == pytest.approx(0.0, abs=HEADING_TOL)
    result = _track((1.0, 0.5, math.pi / 2), SceneConditions.clean())
    assert result.psi == pytest.approx(math.pi / 2, abs=HEADING_TOL)


@pytest.mark.parametrize("field", ["front_occlusion", "back_occlusion"])
def test_occluded_marker_is_lost_with_a_reason(field):
    colour = "red" if field == "front_occlusion" else "blue"
    for pose in _poses(8, seed=2):
        result = _track(pose, SceneConditions(**{field: 1.0}))
        assert not result.ok and colour in result.reason
        assert math.isnan(result.x) and math.isnan(result.y) and math.isnan(result.psi) and result.confidence == 0


@pytest.mark.parametrize("fraction", [0.2, 0.3, 0.5, 0.7])
def test_partly_hidden_marker_is_lost_or_right_never_wrong(fraction):
    lost = 0
    for pose in _poses(16, seed=3):
        result = _track(pose, SceneConditions(front_occlusion=fraction, blur_sigma=0.8))
        if not result.ok:
            lost += 1
            assert "red" in result.reason
            continue
        position, heading = _errors(result, pose)
        assert position < POSITION_TOL and heading < HEADING_TOL_PARTLY_HIDDEN
    if fraction >= 0.5:
        assert lost == 16


@pytest.mark.parametrize("red_bgr", [(30, 45, 205), (45, 30, 205), (25, 60, 210), (60, 25, 210)],
                         ids=["hue~2", "hue~177", "hue~5", "hue~174"])
def test_red_found_on_both_sides_of_the_hue_wrap(red_bgr):
    import cv2

    hue = int(cv2.cvtColor(np.uint8([[red_bgr]]), cv2.COLOR_BGR2HSV)[0, 0, 0])
    assert hue <= 6 or hue >= 172  # the case really sits next to 0 or 179
    for pose in _poses(6, seed=4):
        result = _track(pose, SceneConditions(red_bgr=red_bgr))
        assert result.ok, result.reason
        assert _errors(result, pose)[0] < POSITION_TOL


def test_wrong_marker_spacing_is_rejected():
    # a tracker expecting markers 30 mm further apart than drawn must not report a pose
    config = TrackerConfig(front_offset=FRONT_MARKER_OFFSET + 0.03)
    result = MarkerTracker(CAMERA, config).track(
        Frame(render_frame((1.0, 0.5, 0.3), CAMERA, np.random.default_rng(0)), 0.0))
    assert not result.ok and "separation" in result.reason


def test_large_red_object_is_not_a_marker():
    big = Occluder(0.5, 0.5, 0.04, (40, 35, 205))
    result = _track((1.5, 0.6, 0.0), SceneConditions(occluders=(big,)))
    assert result.ok and _errors(result, (1.5, 0.6, 0.0))[0] < POSITION_TOL
    assert any("too large" in blob.reason for blob in TRACKER.last_blobs["red"])
    # alone in view (the real marker hidden), the big red object is not taken for the marker
    result = _track((1.5, 0.6, 0.0), SceneConditions(occluders=(big,), front_occlusion=1.0))
    assert not result.ok and "too large" in result.reason


def test_second_plausible_marker_is_ambiguous_not_a_guess():
    pose = (1.0, 0.5, 0.0)
    # a red disc of marker size as far behind the blue marker as the real red one is ahead
    decoy = Occluder(1.0 - 0.06 - 0.12, 0.5, 0.015, (40, 35, 205))
    result = _track(pose, SceneConditions(occluders=(decoy,)))
    assert not result.ok and "ambiguous" in result.reason
    # a decoy far away leaves one plausible pair: tracked, with reduced confidence
    far = Occluder(1.5, 0.8, 0.015, (40, 35, 205))
    result = _track(pose, SceneConditions(occluders=(far,)))
    assert result.ok and _errors(result, pose)[0] < POSITION_TOL and result.confidence <= 0.5


@pytest.mark.parametrize(
    "conditions",
    [SceneConditions(brightness=0.45, noise_std=3), SceneConditions(brightness=1.4),
     SceneConditions(gradient=0.5, gradient_angle=2.0, noise_std=3), SceneConditions(noise_std=6, blur_sigma=1.2),
     SceneConditions(glare=25), SceneConditions(brightness=0.12)],
    ids=["dim", "bright", "gradient", "noisy-blurred", "glare", "nearly-dark"],
)
def test_lighting_changes_tracked_or_lost_never_wrong(conditions):
    tracked = 0
    for pose in _poses(15, seed=5):
        result = _track(pose, conditions)
        if result.ok:
            tracked += 1
            position, heading = _errors(result, pose)
            assert position < POSITION_TOL and heading < HEADING_TOL
        else:
            assert result.reason
    if conditions.brightness >= 0.45:
        assert tracked >= 12  # moderate lighting changes must not stop tracking


def test_empty_tank_and_bad_frames():
    empty = render_frame((1.0, 0.5, 0.0), CAMERA, np.random.default_rng(0),
                         SceneConditions(front_occlusion=1.0, back_occlusion=1.0))
    result = TRACKER.track(Frame(empty, 0.0))
    assert not result.ok and "not found" in result.reason
    wrong_size = TRACKER.track(Frame(np.zeros((100, 120, 3), np.uint8), 0.0))  # a clear reason, not an exception
    assert not wrong_size.ok and "frame is 120x100 px but the calibration is for 640x360 px" in wrong_size.reason
    with pytest.raises(ValueError, match="uint8"):
        TRACKER.track(Frame(np.zeros((360, 640, 3)), 0.0))


def test_from_calibration(tmp_path):
    CAMERA.save(tmp_path / "cal.json")
    tracker = MarkerTracker.from_calibration(tmp_path / "cal.json")
    result = tracker.track(Frame(render_frame((0.7, 0.4, 1.0), CAMERA, np.random.default_rng(0)), 0.0))
    assert result.ok and _errors(result, (0.7, 0.4, 1.0))[0] < POSITION_TOL
