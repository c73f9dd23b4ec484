"""Calibration: homography from synthetic points, dot detection on a rendered frame, JSON round trip, CLI."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from pectoral_gym.hardware.vision.calibrate import detect_dots, fit_homography, main, reprojection_errors, tank_corners
from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.scene import Occluder, SceneConditions, render_frame
from pectoral_gym.hardware.vision.tracker import MarkerTracker
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH

# A camera written down by hand: 250 px/m, Y up, origin at pixel (40, 320), and a small perspective term.
TRUE_H = np.array([[250.0, 8.0, 40.0], [3.0, -250.0, 320.0], [0.004, 0.03, 1.0]])


def _project(points):
    homogeneous = np.c_[points, np.ones(len(points))] @ TRUE_H.T
    return homogeneous[:, :2] / homogeneous[:, 2:]


def test_homography_recovered_from_exact_points():
    tank = np.random.default_rng(0).uniform([0, 0], [TANK_LENGTH, TANK_WIDTH], (8, 2))
    np.testing.assert_allclose(fit_homography(tank, _project(tank)), TRUE_H, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(fit_homography(tank_corners(), _project(tank_corners())), TRUE_H, rtol=1e-9)


def test_noisy_points_give_subpixel_reprojection_error():
    rng = np.random.default_rng(1)
    tank = rng.uniform([0, 0], [TANK_LENGTH, TANK_WIDTH], (30, 2))
    pixels = _project(tank) + rng.normal(0, 0.3, (30, 2))
    camera = CameraModel(640, 360, fit_homography(tank, pixels))
    errors = reprojection_errors(camera, tank, pixels)
    assert np.sqrt(np.mean(errors**2)) < 0.45  # noise of 0.3 px per axis -> ~0.42 px rms, fit removes a little
    centre = np.array([[1.15, 0.575]])
    assert np.linalg.norm(camera.pixel_to_tank(_project(centre)) - centre) < 0.002  # m


def test_degenerate_points_are_rejected():
    with pytest.raises(ValueError, match="at least 4"):
        fit_homography(tank_corners()[:3], _project(tank_corners()[:3]))
    on_a_line = np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [1.5, 0.0]])
    with pytest.raises(ValueError, match="homography"):
        fit_homography(on_a_line, _project(on_a_line))


def _dot_frame(camera):
    dots = tuple(Occluder(x, y, 0.02, (40, 200, 40)) for x, y in tank_corners())
    return render_frame((1.15, 0.6, 0.3), camera, np.random.default_rng(0), SceneConditions(occluders=dots))


def test_corner_dots_detected_in_order():
    camera = CameraModel.default()
    found = detect_dots(_dot_frame(camera))
    np.testing.assert_allclose(found, camera.tank_to_pixel(tank_corners()), atol=0.5)
    with pytest.raises(ValueError, match="found 0 dots"):
        detect_dots(render_frame((1.0, 0.5, 0.0), camera, np.random.default_rng(0)))


def test_cli_from_image_round_trip_through_json(tmp_path):
    camera = CameraModel.default()
    image_path = tmp_path / "dots.png"
    cv2.imwrite(str(image_path), _dot_frame(camera))
    output = tmp_path / "cal.json"
    assert main(["--image", str(image_path), "--out", str(output)]) == 0
    data = json.loads(output.read_text())
    assert data["width"] == 640 and data["height"] == 360 and data["reprojection_rms_px"] < 1e-9
    loaded = CameraModel.load(output)
    points = np.random.default_rng(2).uniform([0, 0], [TANK_LENGTH, TANK_WIDTH], (20, 2))
    # a dot centroid is within ~0.5 px of the true corner: the tank positions agree to a few mm
    assert np.abs(loaded.pixel_to_tank(camera.tank_to_pixel(points)) - points).max() < 0.004
    # the tracker accepts the file
    frame = render_frame((0.8, 0.4, -1.0), camera, np.random.default_rng(3))
    result = MarkerTracker.from_calibration(output).track((frame, 0.0))
    assert result.ok and abs(result.x - 0.8) < 0.006 and abs(result.y - 0.4) < 0.006


def test_cli_corners_points_and_emulator(tmp_path, capsys):
    corners = [f"{u},{v}" for u, v in _project(tank_corners())]
    assert main(["--corners", *corners, "--size", "640x360", "--out", str(tmp_path / "a.json")]) == 0
    np.testing.assert_allclose(CameraModel.load(tmp_path / "a.json").homography, TRUE_H, rtol=1e-9)
    tank = np.array([[0.2, 0.1], [2.0, 0.2], [2.1, 1.0], [0.3, 1.1], [1.1, 0.6], [0.7, 0.9]])
    points = [f"{x},{y}:{u},{v}" for (x, y), (u, v) in zip(tank, _project(tank), strict=True)]
    assert main(["--points", *points, "--size", "640x360", "--out", str(tmp_path / "b.json")]) == 0
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert report["points"] == 6 and report["reprojection_max_px"] < 1e-9
    assert main(["--from-emulator", "--out", str(tmp_path / "c.json")]) == 0
    np.testing.assert_allclose(CameraModel.load(tmp_path / "c.json").homography, CameraModel.default().homography,
                               rtol=1e-9, atol=1e-12)


def test_cli_errors(tmp_path):
    with pytest.raises(SystemExit):
        main(["--corners", "1,2", "3,4", "5,6", "7,8"])  # no --size
    with pytest.raises(SystemExit):
        main(["--points", "1,2:3", "--size", "640x360"])
    with pytest.raises(SystemExit):
        main(["--image", str(tmp_path / "missing.png")])


def test_overlay_draws_the_calibrated_outline(tmp_path):
    overlay = tmp_path / "overlay.png"
    assert main(["--from-emulator", "--out", str(tmp_path / "c.json"), "--overlay", str(overlay)]) == 0
    image = cv2.imread(str(overlay))
    camera = CameraModel.default()
    u, v = np.rint(camera.tank_to_pixel((TANK_LENGTH / 2, 0.0))).astype(int)  # middle of the near wall
    b, g, r = image[v, u].astype(int)
    assert r > 200 and b < 80  # the orange outline
    u, v = np.rint(camera.tank_to_pixel((TANK_LENGTH / 2, TANK_WIDTH / 4))).astype(int)
    assert abs(int(image[v, u, 0]) - int(image[v, u, 2])) < 40  # no outline inside the tank


@pytest.mark.parametrize(("args", "message"), [
    (["--from-emulator", "--out", "{tmp}/missing/cal.json"], "cannot write"),
    (["--from-emulator", "--dot-hue", "500"], "0..179"),
    (["--from-emulator", "--dot-hue", "30"], "only with --image"),
    (["--from-emulator", "--size", "1280x720"], "does not match"),
    (["--from-emulator", "--frame", "{tmp}/f.png"], "--frame"),
    (["--from-emulator", "--overlay", "{tmp}/missing/o.png"], "cannot write the overlay"),
    (["--from-emulator", "--overlay", "{tmp}/o.unknown"], "cannot write the overlay"),
    (["--corners", "1,2", "300,2", "300,200", "1,200", "--size", "0x0"], "width and height"),
])
def test_cli_bad_arguments_are_one_line_errors_with_status_2(tmp_path, capsys, args, message):
    """A bad argument or an unwritable file is an argparse error naming it, never a traceback."""
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    if "--out" not in args:
        args += ["--out", str(tmp_path / "cal.json")]
    with pytest.raises(SystemExit) as exit_info:
        main(args)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1] and err[-1].startswith("pectoral-camera-calibrate: error:")
    assert not (tmp_path / "cal.json").exists()


def test_cli_help_shows_examples_and_defaults(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    assert "examples:" in text and "pectoral-camera-calibrate --image" in text
    assert "default calibration.json" in text and "default 60" in text
