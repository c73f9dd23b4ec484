"""Camera calibration: the pixel <-> tank homography from points whose tank position is known.

Three ways to get the points (``pectoral-camera-calibrate --help``; also
``python -m pectoral_gym.hardware.vision.calibrate``; ``pectoral-calibrate`` is its deprecated name until 0.3.0):

- ``--corners U,V U,V U,V U,V``: the pixels of the tank corners (0, 0), (L, 0), (L, W), (0, W), read off a frame
  in any image viewer; ``--points X,Y:U,V ...`` for any other >= 4 known points.
- ``--image FRAME.png``: green dots (or ``--dot-hue``) placed on the four tank corners are found by colour;
  the dot lowest-left in the image is the tank origin, the one lowest-right is (L, 0).
- ``--from-emulator``: the emulator's camera model, for dry runs.

The result is the calibration JSON the tracker reads (``homography`` tank metres -> pixels, ``width``,
``height``) plus the points used and the reprojection error, which is printed. Four points fit exactly and
cannot reveal a mistake: give more when you can.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

from pectoral_gym.hardware.vision.cameramodel import CameraModel, fit_homography
from pectoral_gym.hardware.vision.scene import render_frame
from pectoral_gym.hardware.vision.tracker import draw_overlay
from pectoral_gym.model.params import TANK_LENGTH, TANK_WIDTH
from pectoral_gym.tools.cli_common import HelpFormatter, prog_name

__all__ = ["build_parser", "detect_dots", "fit_homography", "main", "reprojection_errors", "tank_corners"]


def tank_corners() -> np.ndarray:
    """Tank corners (4, 2) [m] in calibration order: (0, 0), (L, 0), (L, W), (0, W)."""
    return np.array([[0.0, 0.0], [TANK_LENGTH, 0.0], [TANK_LENGTH, TANK_WIDTH], [0.0, TANK_WIDTH]])


def reprojection_errors(camera: CameraModel, tank_points: np.ndarray, pixel_points: np.ndarray) -> np.ndarray:
    """Distance [px] between each measured pixel and the projection of its tank point."""
    return np.linalg.norm(camera.tank_to_pixel(tank_points) - np.asarray(pixel_points, dtype=float), axis=1)


def detect_dots(image: np.ndarray, hue: int = 60, hue_tolerance: int = 15, min_area: int = 6) -> np.ndarray:
    """Centroids (4, 2) [px] of four saturated dots of one hue, ordered as :func:`tank_corners`.

    The image is assumed to show the tank with its origin at the lower left and X to the right (the emulator's
    view). Raises ValueError unless exactly four dots are found.
    """
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    low, high = max(hue - hue_tolerance, 0), min(hue + hue_tolerance, 179)
    mask = cv2.inRange(hsv, (low, 100, 50), (high, 255, 255))
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    count, _, stats, centroids = cv2.connectedComponentsWithStats(mask)
    dots = centroids[1:][stats[1:, cv2.CC_STAT_AREA] >= min_area]
    if len(dots) != 4:
        raise ValueError(f"found {len(dots)} dots of hue {hue} +- {hue_tolerance} (OpenCV 0-179 scale), need 4")
    u_plus_v, u_minus_v = dots.sum(axis=1), dots[:, 0] - dots[:, 1]
    order = [np.argmin(u_minus_v), np.argmax(u_plus_v), np.argmax(u_minus_v), np.argmin(u_plus_v)]
    if len(set(order)) != 4:
        raise ValueError("the four dots do not form a quadrilateral with one dot per image corner")
    return dots[order]


def _pair(text: str) -> tuple[float, float]:
    try:
        a, b = (float(part) for part in text.split(","))
    except ValueError as error:
        raise argparse.ArgumentTypeError(f"expected two comma-separated numbers like 12.5,340, got {text!r}") from error
    return a, b


def _point(text: str) -> tuple[tuple[float, float], tuple[float, float]]:
    if text.count(":") != 1:
        raise argparse.ArgumentTypeError(f"expected X,Y:U,V (tank metres : pixels), got {text!r}")
    tank, pixel = text.split(":")
    return _pair(tank), _pair(pixel)


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(part) for part in text.lower().split("x"))
    except ValueError as error:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT in pixels like 640x360, got {text!r}") from error
    return width, height


_EXAMPLES = """examples:
  pectoral-camera-calibrate --image frame.png --out calibration.json --overlay check.png
  pectoral-camera-calibrate --corners 40,320 615,305 600,40 52,30 --size 640x360 --out calibration.json
  pectoral-camera-calibrate --points 0.2,0.1:90,296 2.0,0.2:540,270 2.1,1.0:565,70 \\
      0.3,1.1:115,45 1.1,0.6:315,170 --size 640x360 --frame frame.png --overlay check.png
  pectoral-camera-calibrate --from-emulator --out emulator.json

Calibrate at the resolution the camera runs at during deployment: pectoral-deploy refuses a calibration made for
another image size. Exit status: 0 written; 2 a bad argument or an unreadable/unwritable file."""


def _hue(text: str) -> int:
    try:
        hue = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer hue in 0..179 (OpenCV scale), got {text!r}") from None
    if not 0 <= hue <= 179:
        raise argparse.ArgumentTypeError(f"the hue must be in 0..179 (OpenCV's scale: degrees / 2), got {hue}")
    return hue


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pectoral-camera-calibrate``."""
    parser = argparse.ArgumentParser(
        prog=prog_name("pectoral-camera-calibrate", "pectoral_gym.hardware.vision.calibrate"),
        description="Compute the pixel <-> tank homography of the overhead camera and write the calibration JSON.",
        epilog=_EXAMPLES, formatter_class=HelpFormatter,
    )
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--corners", nargs=4, type=_pair, metavar="U,V",
                        help="pixels of the tank corners (0,0), (L,0), (L,W), (0,W) in this order")
    source.add_argument("--points", nargs="+", type=_point, metavar="X,Y:U,V",
                        help=">= 4 known points: tank position [m] : pixel")
    source.add_argument("--image", type=Path, metavar="FRAME",
                        help="a frame with coloured dots on the four tank corners (origin lower left)")
    source.add_argument("--from-emulator", action="store_true", help="the emulator's camera model (dry runs)")
    parser.add_argument("--size", type=_size, metavar="WxH",
                        help="image size [px] (needed with --corners/--points; with --image or --from-emulator it "
                             "must match the image)")
    parser.add_argument("--dot-hue", type=_hue, default=None, metavar="H",
                        help="--image: hue of the corner dots on OpenCV's 0-179 scale (default 60, green)")
    parser.add_argument("--overlay", type=Path, metavar="PNG",
                        help="also write the frame with the calibrated tank outline and a 0.25 m grid, to check by eye "
                             "(default: none)")
    parser.add_argument("--frame", type=Path, metavar="FRAME",
                        help="background frame of --overlay with --corners/--points (default: white)")
    parser.add_argument("--out", type=Path, default=Path("calibration.json"), metavar="FILE",
                        help="calibration file to write (default calibration.json)")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.frame is not None and (args.overlay is None or args.corners is None and args.points is None):
        parser.error("--frame is the background of --overlay with --corners/--points; it applies only with those")
    if args.dot_hue is not None and args.image is None:
        parser.error("--dot-hue applies only with --image")
    if args.overlay is not None and not (args.overlay.parent.is_dir() and cv2.haveImageWriter(str(args.overlay))):
        parser.error(f"cannot write the overlay {args.overlay}: no such folder or no image writer for its extension")
    background = None
    if args.from_emulator:
        reference = CameraModel.default()
        background = render_frame((TANK_LENGTH / 2, TANK_WIDTH / 2, 0.0), reference, np.random.default_rng(0))
        tank, size, source = tank_corners(), (reference.width, reference.height), "emulator"
        pixels = reference.tank_to_pixel(tank)
    elif args.image is not None:
        image = cv2.imread(str(args.image), cv2.IMREAD_COLOR)
        if image is None:
            parser.error(f"cannot read image {args.image}")
        try:
            pixels = detect_dots(image, hue=60 if args.dot_hue is None else args.dot_hue)
        except ValueError as error:
            parser.error(str(error))
        tank, size, source = tank_corners(), (image.shape[1], image.shape[0]), f"dots in {args.image}"
        background = image
    else:
        if args.size is None:
            parser.error("--size WxH is required with --corners or --points")
        if args.corners:
            tank, pixels, source = tank_corners(), np.array(args.corners), "corners"
        else:
            tank = np.array([point[0] for point in args.points])
            pixels = np.array([point[1] for point in args.points])
            source = "points"
        size = args.size
        if args.frame is not None:
            background = cv2.imread(str(args.frame), cv2.IMREAD_COLOR)
            if background is None:
                parser.error(f"cannot read frame {args.frame}")
    if args.size is not None and tuple(args.size) != tuple(size):
        parser.error(f"--size {args.size[0]}x{args.size[1]} does not match the {source} image, {size[0]}x{size[1]} px")
    try:
        camera = CameraModel(size[0], size[1], fit_homography(tank, pixels))
    except ValueError as error:
        parser.error(str(error))
    errors = reprojection_errors(camera, tank, pixels)
    rms, worst = float(np.sqrt(np.mean(errors**2))), float(errors.max())
    try:
        camera.save(
            args.out,
            source=source,
            tank_points=np.asarray(tank).tolist(),
            pixel_points=np.asarray(pixels).tolist(),
            reprojection_rms_px=rms,
            reprojection_max_px=worst,
        )
    except OSError as error:
        parser.error(f"cannot write {args.out}: {error}")
    if args.overlay is not None:
        if background is None:
            background = np.full((camera.height, camera.width, 3), 255, np.uint8)
        elif background.shape[:2] != (camera.height, camera.width):
            parser.error(f"--frame {args.frame} is {background.shape[1]}x{background.shape[0]} px, not the "
                         f"calibrated {camera.width}x{camera.height}")
        canvas = draw_overlay(background, camera)
        for u, v in np.asarray(pixels):
            cv2.drawMarker(canvas, (int(round(u)), int(round(v))), (255, 0, 255), cv2.MARKER_CROSS, 12, 1)
        try:
            written = cv2.imwrite(str(args.overlay), canvas)
        except cv2.error:
            written = False
        if not written:
            parser.error(f"cannot write the overlay {args.overlay}")
    scale = camera.pixels_per_metre((TANK_LENGTH / 2, TANK_WIDTH / 2))
    print(json.dumps({"output": str(args.out), "points": len(tank), "reprojection_rms_px": round(rms, 4),
                      "reprojection_max_px": round(worst, 4), "pixels_per_metre_at_centre": round(scale, 2)}))
    if len(tank) == 4:
        print("note: 4 points fit exactly; the reprojection error cannot reveal a mistake. Use more points.",
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
