"""Camera frames over TCP: an emulator process serves its rendered camera, the tracker side reads it.

Wire format (one message per frame, big-endian)::

    b"PGF1" | timestamp float64 [s, sender's time.monotonic()] | length uint32 | encoded image of `length` bytes

The image is BMP by default (uncompressed and lossless: the tracker sees exactly what was rendered, and
neither side spends CPU on a codec; about 0.7 MB a frame at 640 x 360, 21 MB/s at 30 frames/s, for loopback
or a wired LAN), PNG (lossless, half the bytes, ~15 ms to encode) or JPEG.
"""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
import time

import cv2
import numpy as np

from pectoral_gym.hardware.vision.frames import Frame, FrameSource, NewestSlot

__all__ = ["ENCODINGS", "FrameServer", "NetworkCamera"]

ENCODINGS = ("bmp", "png", "jpg")
_MAGIC = b"PGF1"
_HEADER = struct.Struct("!4sdI")
_MAX_MESSAGE = 32 * 1024 * 1024  # bytes; a frame bigger than this is a corrupt stream


def _encode(frame: Frame, encoding: str) -> bytes:
    params = {"png": [cv2.IMWRITE_PNG_COMPRESSION, 1], "jpg": [cv2.IMWRITE_JPEG_QUALITY, 95], "bmp": []}[encoding]
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
        encoding: ``"bmp"`` (uncompressed, lossless, default), ``"png"`` (lossless) or ``"jpg"``.
    """

    def __init__(
        self,
        source: FrameSource | None = None,
        host: str = "127.0.0.1",
        port: int = 0,
        fps: float = 30.0,
        encoding: str = "bmp",
    ) -> None:
        if encoding not in ENCODINGS:
            raise ValueError(f"encoding must be one of {ENCODINGS}, got {encoding!r}")
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
        self._slot = NewestSlot()
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
