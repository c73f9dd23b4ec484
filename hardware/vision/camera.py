"""Frame sources: a real camera, a video file, the emulator's renderer, and frames over TCP.

Every source implements :class:`FrameSource`: ``read()`` returns the newest :class:`Frame` not returned before, or
``None`` when there is none (yet) or the source is lost; it never blocks for long and never hands out a stale frame
twice. Timestamps are seconds on the ``time.monotonic()`` clock (see :mod:`pectoral_gym.hardware.vision.frames`).
:class:`FrameServer` and :class:`NetworkCamera` (frames over TCP) live in :mod:`pectoral_gym.hardware.vision.netcamera`
and are re-exported here.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from pectoral_gym.hardware.vision.cameramodel import CameraModel
from pectoral_gym.hardware.vision.frames import CameraLostError, Frame, FrameSource, NewestSlot
from pectoral_gym.hardware.vision.netcamera import FrameServer, NetworkCamera
from pectoral_gym.hardware.vision.scene import SceneConditions, render_frame, warm_up

__all__ = [
    "CameraLostError",
    "EmulatedCamera",
    "Frame",
    "FrameServer",
    "FrameSource",
    "NetworkCamera",
    "OpenCVCamera",
    "VideoFileSource",
    "open_source",
]

Pose = tuple[float, float, float]


class EmulatedCamera:
    """Renders the overhead view of an emulated fish on every ``read()``.

    The frame's stamp is the instant of the pose it shows (``pose_fn``'s), taken before rendering; read
    it through :class:`pectoral_gym.hardware.vision.frames.FrameGrabber` to render in a thread of its own.

    A perfectly noise-free renderer (``noise_std=0``) of a fish at rest repeats its image exactly, which
    :class:`pectoral_gym.hardware.vision.framecheck.FrameCheck` rightly cannot tell from a frozen camera; the default
    conditions carry sensor noise (``noise_std=2``) as a real sensor does.

    Args:
        pose_fn: Returns ``(pose, timestamp)`` of the fish now: pose (X, Y, psi) [m, rad], timestamp on the
            monotonic clock (or the emulator's accelerated clock). Returning ``None`` emulates a lost camera.
        camera: Camera model; ``None`` means :meth:`CameraModel.default`.
        conditions: Imperfections of the image; can be replaced at any time through the ``conditions`` attribute.
        seed: Seed of the noise generators (image noise, and pose noise from a generator of its own).
        pose_noise: ``(metres, radians)``: standard deviations of independent Gaussian noise added to X and
            Y, and to psi, of each rendered pose (a tracker's measurement noise seen end to end); can be
            changed through the ``pose_noise`` attribute.
    """

    def __init__(
        self,
        pose_fn: Callable[[], tuple[Pose, float] | None],
        camera: CameraModel | None = None,
        conditions: SceneConditions | None = None,
        seed: int | None = None,
        pose_noise: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        self.pose_fn = pose_fn
        self.camera = CameraModel.default() if camera is None else camera
        self.conditions = SceneConditions() if conditions is None else conditions
        self.pose_noise = pose_noise
        self._rng = np.random.default_rng(seed)
        self._pose_rng = np.random.default_rng(None if seed is None else [int(seed), 1])
        self._last_timestamp: float | None = None
        self._closed = False
        warm_up()  # the renderer's kernels compiled here, not at the camera thread's first frame

    @property
    def pose_noise(self) -> tuple[float, float]:
        """``(metres, radians)`` standard deviations of the pose noise."""
        return self._pose_noise

    @pose_noise.setter
    def pose_noise(self, value: tuple[float, float]) -> None:
        try:
            metres, radians = (float(v) for v in value)
        except (TypeError, ValueError):
            raise ValueError(f"pose_noise must be (metres, radians), got {value!r}") from None
        if not (math.isfinite(metres) and math.isfinite(radians) and metres >= 0 and radians >= 0):
            raise ValueError(f"pose_noise must be finite and >= 0 (metres, radians), got {value!r}")
        self._pose_noise = (metres, radians)

    def read(self) -> Frame | None:
        """Render the fish where ``pose_fn`` says it is now (``None`` if closed, lost, or no time has passed)."""
        if self._closed:
            return None
        sample = self.pose_fn()
        if sample is None:
            return None
        pose, timestamp = sample
        if self._last_timestamp is not None and timestamp <= self._last_timestamp:
            return None
        self._last_timestamp = float(timestamp)
        metres, radians = self._pose_noise
        if metres > 0 or radians > 0:
            dx, dy, dpsi = self._pose_rng.standard_normal(3) * (metres, metres, radians)
            pose = (pose[0] + dx, pose[1] + dy, pose[2] + dpsi)
        return Frame(render_frame(pose, self.camera, self._rng, self.conditions), float(timestamp))

    def close(self) -> None:
        """Stop producing frames."""
        self._closed = True


class OpenCVCamera:
    """A ``cv2.VideoCapture`` device or stream URL, read by a grabber thread that keeps only the newest frame.

    ``VideoCapture.read()`` can block for a long time when a device or stream disappears, so it runs in a daemon
    thread; ``read()`` here waits at most ``read_timeout`` and reports a lost camera as ``None`` with
    :attr:`lost_reason` set. Opening a device that does not exist raises :class:`CameraLostError`.

    Args:
        index_or_url: Camera index (``0``) or a URL/pipeline that OpenCV can open.
        width: Requested image width [px] (``None``: the device default).
        height: Requested image height [px].
        read_timeout: Longest wait for a new frame in ``read()`` [s].
        stale_after: No frame for this long means the camera is lost [s].
    """

    def __init__(
        self,
        index_or_url: int | str,
        width: int | None = None,
        height: int | None = None,
        read_timeout: float = 0.2,
        stale_after: float = 1.0,
    ) -> None:
        self.read_timeout = float(read_timeout)
        self.stale_after = float(stale_after)
        if isinstance(index_or_url, str):
            # Stream backends (FFmpeg) honour these; without them a dead stream can block for ~30 s or more.
            timeout_ms = int(1000 * max(stale_after, 0.5))
            params = [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, 2 * timeout_ms, cv2.CAP_PROP_READ_TIMEOUT_MSEC, timeout_ms]
            self._capture = cv2.VideoCapture(index_or_url, cv2.CAP_ANY, params)
        else:
            self._capture = cv2.VideoCapture(int(index_or_url))
        if not self._capture.isOpened():
            self._capture.release()
            raise CameraLostError(f"cannot open camera {index_or_url!r} (check the index/URL and permissions)")
        self._capture.set(cv2.CAP_PROP_BUFFERSIZE, 1)  # fewer queued old frames where the backend supports it
        if width:
            self._capture.set(cv2.CAP_PROP_FRAME_WIDTH, width)
        if height:
            self._capture.set(cv2.CAP_PROP_FRAME_HEIGHT, height)
        self.source = index_or_url
        self.lost_reason = ""
        self._slot = NewestSlot()
        self._last_frame_time = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._grab_loop, name=f"camera-{index_or_url}", daemon=True)
        self._thread.start()

    def _grab_loop(self) -> None:
        while not self._stop.is_set():
            ok, image = self._capture.read()
            now = time.monotonic()
            if not ok or image is None:
                self.lost_reason = f"camera {self.source!r} returned no frame (unplugged or stream ended)"
                self._slot.wake()
                return
            self._last_frame_time = now
            self._slot.put(Frame(image, now))

    @property
    def lost(self) -> bool:
        """True once the camera stopped delivering frames."""
        if not self.lost_reason and time.monotonic() - self._last_frame_time > self.stale_after:
            self.lost_reason = f"no frame from camera {self.source!r} for more than {self.stale_after:.2f} s"
        return bool(self.lost_reason)

    def read(self) -> Frame | None:
        """Newest frame not returned before, waiting up to ``read_timeout``; ``None`` if none or lost."""
        if self._stop.is_set():
            return None
        frame = self._slot.take(0.0 if self.lost_reason else self.read_timeout)
        if frame is None or time.monotonic() - frame.timestamp > self.stale_after:
            self.lost  # noqa: B018 - updates lost_reason when the camera went quiet
            return None
        return frame

    def close(self) -> None:
        """Stop the grabber and release the device (safe to call twice)."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=1.0)
        if not self._thread.is_alive():  # a grabber stuck in read() keeps the device; it is a daemon thread
            self._capture.release()

class VideoFileSource:
    """Frames of a video file, in order; ``None`` at the end (or loops).

    Timestamps are the time the file was opened (monotonic) plus each frame's position in the file, so a recorded
    run replays with its original spacing even when read faster than real time.

    Args:
        path: Video file readable by OpenCV.
        loop: Start again at the end instead of returning ``None``.
    """

    def __init__(self, path: str | os.PathLike, loop: bool = False) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"video file not found: {self.path}")
        self._capture = cv2.VideoCapture(str(self.path))
        if not self._capture.isOpened():
            raise CameraLostError(f"OpenCV cannot decode video file {self.path}")
        fps = self._capture.get(cv2.CAP_PROP_FPS)
        self.fps = float(fps) if fps and np.isfinite(fps) and fps > 0 else 30.0
        self.loop = loop
        self._start = time.monotonic()
        self._index = 0
        self._closed = False

    def read(self) -> Frame | None:
        """The next frame of the file, or ``None`` at its end or after ``close()``."""
        if self._closed:
            return None
        ok, image = self._capture.read()
        if not ok and self.loop and self._index > 0:
            self._capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok, image = self._capture.read()
        if not ok or image is None:
            return None
        timestamp = self._start + self._index / self.fps
        self._index += 1
        return Frame(image, timestamp)

    def close(self) -> None:
        """Release the file (safe to call twice)."""
        if not self._closed:
            self._closed = True
            self._capture.release()

def open_source(spec: str | int) -> FrameSource:
    """Open a frame source from a command-line spec.

    Args:
        spec: ``"0"`` (or an int): camera index; ``"emu://host:port"``: an emulator's :class:`FrameServer`;
            ``rtsp://``, ``http(s)://`` URLs: an OpenCV stream; an existing path: a video file.

    Raises:
        ValueError: The spec is none of these.
    """
    if isinstance(spec, int) or (isinstance(spec, str) and spec.strip().isdigit()):
        return OpenCVCamera(int(spec))
    spec = str(spec).strip()
    if spec.startswith("emu://"):
        host, _, port = spec[len("emu://") :].rpartition(":")
        if not host or not port.isdigit():
            raise ValueError(f"camera spec {spec!r}: expected emu://HOST:PORT, e.g. emu://127.0.0.1:5600")
        return NetworkCamera(host, int(port))
    if spec.split("://", 1)[0] in ("rtsp", "http", "https", "udp", "tcp"):
        return OpenCVCamera(spec)
    if Path(spec).is_file():
        return VideoFileSource(spec)
    raise ValueError(
        f"camera spec {spec!r} is not a camera index, an emu://HOST:PORT address, a stream URL "
        "or an existing video file"
    )
