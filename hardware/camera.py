"""Frame sources: a real camera, a video file, the emulator's renderer, and frames over TCP.

Every source implements :class:`FrameSource`: ``read()`` returns the newest :class:`Frame` not returned before, or
``None`` when there is none (yet) or the source is lost; it never blocks for long and never hands out a stale frame
twice. Timestamps are seconds on the ``time.monotonic()`` clock of this machine (on Linux the same clock in every
process, so a frame served by an emulator process on the same host keeps its capture time).

Wire format of :class:`FrameServer` / :class:`NetworkCamera` (one message per frame, big-endian)::

    b"PGF1" | timestamp float64 [s] | length uint32 | encoded image (PNG by default, or JPEG) of `length` bytes
"""

from __future__ import annotations

import contextlib
import os
import socket
import struct
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple, Protocol, runtime_checkable

import cv2
import numpy as np

from hardware.scene import CameraModel, SceneConditions, render_frame

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


class Frame(NamedTuple):
    """One camera image.

    Attributes:
        image: (H, W, 3) uint8 BGR image.
        timestamp: Capture time [s] on the ``time.monotonic()`` clock.
    """

    image: np.ndarray
    timestamp: float


@runtime_checkable
class FrameSource(Protocol):
    """Anything that yields timestamped frames."""

    def read(self) -> Frame | None:
        """Return the newest frame not returned before, or ``None`` if there is none or the source is lost."""
        ...

    def close(self) -> None:
        """Release the device, file or connection (safe to call twice)."""
        ...


class CameraLostError(RuntimeError):
    """A camera could not be opened."""


class EmulatedCamera:
    """Renders the overhead view of an emulated fish on every ``read()``.

    Args:
        pose_fn: Returns ``(pose, timestamp)`` of the fish now: pose (X, Y, psi) [m, rad], timestamp on the
            monotonic clock (or the emulator's accelerated clock). Returning ``None`` emulates a lost camera.
        camera: Camera model; ``None`` means :meth:`CameraModel.default`.
        conditions: Imperfections of the image; can be replaced at any time through the ``conditions`` attribute.
        seed: Seed of the noise generator.
    """

    def __init__(
        self,
        pose_fn: Callable[[], tuple[Pose, float] | None],
        camera: CameraModel | None = None,
        conditions: SceneConditions | None = None,
        seed: int | None = None,
    ) -> None:
        self.pose_fn = pose_fn
        self.camera = CameraModel.default() if camera is None else camera
        self.conditions = SceneConditions() if conditions is None else conditions
        self._rng = np.random.default_rng(seed)
        self._last_timestamp: float | None = None
        self._closed = False

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
        return Frame(render_frame(pose, self.camera, self._rng, self.conditions), float(timestamp))

    def close(self) -> None:
        """Stop producing frames."""
        self._closed = True


class _NewestSlot:
    """A one-item mailbox: the producer overwrites, the consumer takes each item at most once."""

    def __init__(self) -> None:
        self._condition = threading.Condition()
        self._item: Frame | None = None
        self._sequence = 0
        self._taken = 0

    def put(self, item: Frame) -> None:
        with self._condition:
            self._item = item
            self._sequence += 1
            self._condition.notify_all()

    def take(self, timeout: float) -> Frame | None:
        with self._condition:
            if self._sequence == self._taken and timeout > 0:
                self._condition.wait_for(lambda: self._sequence != self._taken, timeout)
            if self._sequence == self._taken:
                return None
            self._taken = self._sequence
            return self._item

    def wake(self) -> None:
        with self._condition:
            self._condition.notify_all()


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
        self._slot = _NewestSlot()
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


_MAGIC = b"PGF1"
_HEADER = struct.Struct("!4sdI")
_MAX_MESSAGE = 32 * 1024 * 1024  # bytes; a frame bigger than this is a corrupt stream


def _encode(frame: Frame, encoding: str) -> bytes:
    params = [cv2.IMWRITE_PNG_COMPRESSION, 1] if encoding == "png" else [cv2.IMWRITE_JPEG_QUALITY, 95]
    ok, data = cv2.imencode(f".{encoding}", frame.image, params)
    if not ok:
        raise ValueError(f"cannot encode a frame of shape {frame.image.shape} as {encoding}")
    payload = data.tobytes()
    return _HEADER.pack(_MAGIC, frame.timestamp, len(payload)) + payload


def _recv_exact(sock: socket.socket, size: int) -> bytes:
    chunks, remaining = [], size
    while remaining:
        chunk = sock.recv(min(remaining, 1 << 20))
        if not chunk:
            raise ConnectionError("frame server closed the connection")
        chunks.append(chunk)
        remaining -= len(chunk)
    return b"".join(chunks)


class FrameServer:
    """Serves frames over TCP to any number of :class:`NetworkCamera` clients.

    Frames come either from ``publish(frame)`` (an emulator that renders on its own clock) or from a ``source``
    polled at ``fps`` by a producer thread. Each client gets the newest frame; slow clients skip frames.

    Args:
        source: Optional frame source to poll.
        host: Interface to listen on.
        port: TCP port (0 picks a free one; see :attr:`port`).
        fps: Polling rate of ``source`` [1/s].
        encoding: ``"png"`` (lossless, default) or ``"jpg"``.
    """

    def __init__(
        self,
        source: FrameSource | None = None,
        host: str = "127.0.0.1",
        port: int = 0,
        fps: float = 30.0,
        encoding: str = "png",
    ) -> None:
        if encoding not in ("png", "jpg"):
            raise ValueError(f"encoding must be 'png' or 'jpg', got {encoding!r}")
        if fps <= 0:
            raise ValueError(f"fps must be > 0, got {fps}")
        self.encoding = encoding
        self._listener = socket.create_server((host, port))
        self._listener.settimeout(0.2)
        self.host, self.port = self._listener.getsockname()[:2]
        self._condition = threading.Condition()
        self._message: bytes | None = None
        self._sequence = 0
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._accept_loop, name="frame-server", daemon=True)]
        if source is not None:
            self._threads.append(
                threading.Thread(target=self._poll_loop, args=(source, 1.0 / fps), name="frame-poll", daemon=True)
            )
        for thread in self._threads:
            thread.start()

    @property
    def spec(self) -> str:
        """The ``emu://host:port`` spec that :func:`open_source` connects to."""
        return f"emu://{self.host}:{self.port}"

    def publish(self, frame: Frame) -> None:
        """Make ``frame`` the newest frame sent to every client."""
        message = _encode(frame, self.encoding)
        with self._condition:
            self._message = message
            self._sequence += 1
            self._condition.notify_all()

    def _poll_loop(self, source: FrameSource, period: float) -> None:
        next_time = time.monotonic()
        while not self._stop.is_set():
            frame = source.read()
            if frame is not None:
                self.publish(frame)
            next_time = max(next_time + period, time.monotonic())
            self._stop.wait(max(0.0, next_time - time.monotonic()))

    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            try:
                client, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            threading.Thread(target=self._serve, args=(client,), name="frame-client", daemon=True).start()

    def _serve(self, client: socket.socket) -> None:
        sent = 0
        with client:
            while not self._stop.is_set():
                with self._condition:
                    self._condition.wait_for(lambda last=sent: self._sequence != last or self._stop.is_set(), 0.2)
                    if self._sequence == sent:
                        continue
                    message, sent = self._message, self._sequence
                try:
                    client.sendall(message)
                except OSError:
                    return

    def close(self) -> None:
        """Stop serving and drop every client (safe to call twice)."""
        if self._stop.is_set():
            return
        self._stop.set()
        with self._condition:
            self._condition.notify_all()
        self._listener.close()
        for thread in self._threads:
            thread.join(timeout=1.0)


class NetworkCamera:
    """Client of a :class:`FrameServer`: a receiver thread keeps the newest frame; reconnects if dropped.

    Args:
        host: Server host.
        port: Server port.
        read_timeout: Longest wait for a new frame in ``read()`` [s].
        stale_after: No frame for this long means the camera is lost [s].
        connect_timeout: Timeout of each connection attempt [s].
    """

    def __init__(
        self,
        host: str,
        port: int,
        read_timeout: float = 0.2,
        stale_after: float = 1.0,
        connect_timeout: float = 1.0,
    ) -> None:
        self.host, self.port = host, int(port)
        self.read_timeout = float(read_timeout)
        self.stale_after = float(stale_after)
        self.connect_timeout = float(connect_timeout)
        self.lost_reason = ""
        self.frames_received = 0
        self._slot = _NewestSlot()
        self._last_frame_time = time.monotonic()
        self._stop = threading.Event()
        self._socket: socket.socket | None = None
        self._thread = threading.Thread(target=self._receive_loop, name=f"emu-{host}:{port}", daemon=True)
        self._thread.start()

    def _receive_loop(self) -> None:
        while not self._stop.is_set():
            try:
                with socket.create_connection((self.host, self.port), timeout=self.connect_timeout) as sock:
                    sock.settimeout(self.stale_after)
                    self._socket = sock
                    while not self._stop.is_set():
                        magic, timestamp, length = _HEADER.unpack(_recv_exact(sock, _HEADER.size))
                        if magic != _MAGIC or length > _MAX_MESSAGE:
                            raise ConnectionError(f"corrupt frame stream from {self.host}:{self.port}")
                        payload = _recv_exact(sock, length)
                        image = cv2.imdecode(np.frombuffer(payload, np.uint8), cv2.IMREAD_COLOR)
                        if image is None:
                            raise ConnectionError("undecodable frame")
                        self._last_frame_time = time.monotonic()
                        self.frames_received += 1
                        self.lost_reason = ""
                        self._slot.put(Frame(image, timestamp))
            except (OSError, ConnectionError, struct.error) as error:
                if not self._stop.is_set():
                    self.lost_reason = f"frame server {self.host}:{self.port}: {error}"
                    self._slot.wake()
                    self._stop.wait(0.2)  # then reconnect
            finally:
                self._socket = None

    @property
    def lost(self) -> bool:
        """True when no frame arrived for ``stale_after`` seconds."""
        quiet = time.monotonic() - self._last_frame_time > self.stale_after
        if quiet and not self.lost_reason:
            self.lost_reason = f"no frame from {self.host}:{self.port} for more than {self.stale_after:.2f} s"
        return quiet

    def read(self) -> Frame | None:
        """Newest frame not returned before, waiting up to ``read_timeout``; ``None`` if none or lost."""
        if self._stop.is_set():
            return None
        frame = self._slot.take(self.read_timeout)
        if frame is None or self.lost:
            return None
        return frame

    def close(self) -> None:
        """Disconnect (safe to call twice)."""
        if self._stop.is_set():
            return
        self._stop.set()
        sock = self._socket
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
        self._thread.join(timeout=2.0)


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
