"""Lossy radio between a :class:`~pectoral_gym.hardware.radio.link.RadioLink` and a robot: delay, jitter, loss, bursts.

:class:`RadioProxy` listens on ``socket://127.0.0.1:PORT`` (its :attr:`~RadioProxy.url`); every
connection to it gets its own connection to ``upstream_url`` (an emulated robot's ``socket://`` URL),
and bytes flow both ways through it. It is frame-aware: it cuts each direction's byte stream into
XBee API frames (start delimiter ``0x7E``, escaped length; ``pectoral_gym.hardware.radio.protocol``) and delays or drops
*whole* frames, so a loss is a lost message, never a damaged stream. Bytes outside any frame are
passed on with the same delay.

Radio conditions (latency, jitter, loss, fades; :class:`pectoral_gym.hardware.radio.channel.RadioChannel`) are in
*robot* seconds, divided by ``speed`` on the wall clock for an emulator running ``speed`` times faster.
Every draw comes from one generator seeded with ``seed``, so the sequence of losses, delays and fades is
the same from run to run (the wall-clock timing of the threads around it is not; for a run that is the
same throughout, use the in-process :class:`pectoral_gym.hardware.radio.pipe.StreamPair` on a
:class:`pectoral_gym.hardware.clock.VirtualClock`).
"""

from __future__ import annotations

import heapq
import itertools
import math
import select
import socket
import threading
import time
from collections.abc import Callable

from pectoral_gym.hardware.radio.channel import ProxyStats, RadioChannel
from pectoral_gym.hardware.radio.xbee import ESCAPE, START

__all__ = ["RadioProxy", "FrameSplitter", "ProxyStats"]  # ProxyStats: from .channel

_POLL = 0.001  # longest wait of the proxy loop [wall s]


class FrameSplitter:
    """Cuts an escaped XBee byte stream into raw frames (delimiter, escaped length, data and checksum)."""

    def __init__(self):
        self._raw = bytearray()
        self._count = 0  # unescaped bytes after the delimiter
        self._high = 0
        self._length: int | None = None
        self._escaped = False
        self._in_frame = False

    def feed(self, data: bytes) -> list[bytes]:
        """Consume ``data``; return the complete units: whole frames, or runs of bytes outside a frame."""
        out: list[bytes] = []
        for byte in data:
            if byte == START:
                if self._raw:
                    out.append(bytes(self._raw))  # garbage, or a frame cut short: passed on as it came
                self._raw = bytearray((byte,))
                self._count, self._length, self._escaped, self._in_frame = 0, None, False, True
                continue
            self._raw.append(byte)
            if not self._in_frame:
                continue
            if self._escaped:
                value, self._escaped = byte ^ 0x20, False
            elif byte == ESCAPE:
                self._escaped = True
                continue
            else:
                value = byte
            self._count += 1
            if self._count == 1:
                self._high = value
            elif self._count == 2:
                self._length = (self._high << 8) | value
            if self._length is not None and self._count == self._length + 3:
                out.append(bytes(self._raw))
                self._raw, self._in_frame = bytearray(), False
        if self._raw and not self._in_frame:
            out.append(bytes(self._raw))
            self._raw = bytearray()
        return out


class RadioProxy:
    """A lossy, delaying radio on loopback between PCs and one robot (see the module docstring).

    Args:
        upstream_url: ``socket://host:port`` of the robot (an :class:`pectoral_gym.hardware.emulator.EmulatedRobot`).
        latency: One-way delay per frame [robot s]: a number, or ``(lo, hi)`` for a uniform draw.
        loss: Probability that a frame is lost, each direction, independently, in ``[0, 1)``.
        burst: ``(fraction, length)``: fades of ``length`` robot seconds covering ``fraction`` of the time
            (``fraction`` in ``[0, 1)``); ``None`` for no fades.
        seed: Seed of every draw (losses, delays, fades).
        speed: Robot seconds per wall second (the emulator's ``speed``).
        reorder: Let a faster frame overtake a slower one of the same direction.
        host: Interface to listen on.

    Attributes:
        url: ``socket://host:port`` for :class:`pectoral_gym.hardware.radio.link.RadioLink`.
        stats: A :class:`ProxyStats`.
        log: ``None``, or a list to which every frame appends ``(wall time, "up"/"down", lost)``.
        drop_if: ``None``, or ``f(direction, raw_frame) -> bool``: frames it returns True for are lost too
            (a scripted loss, for deterministic reproductions).
    """

    def __init__(self, upstream_url: str, latency: float | tuple[float, float] = 0.0, loss: float = 0.0,
                 burst: tuple[float, float] | None = None, seed: int | None = None, speed: float = 1.0,
                 reorder: bool = False, host: str = "127.0.0.1"):
        if not upstream_url.startswith("socket://") or ":" not in upstream_url[9:]:
            raise ValueError(f"RadioProxy: upstream_url must be socket://host:port, got {upstream_url!r}")
        self._upstream = (upstream_url[9:].rsplit(":", 1)[0], int(upstream_url.rsplit(":", 1)[1]))
        if not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"RadioProxy: speed must be a finite number > 0, got {speed!r}")
        try:
            self.channel = RadioChannel(latency, loss, burst, seed, reorder)
        except ValueError as err:
            raise ValueError(f"RadioProxy: {err}") from None
        self.speed = float(speed)
        self.latency, self.loss, self.burst, self.reorder = (self.channel.latency, self.channel.loss, burst,
                                                             self.channel.reorder)
        self.stats = self.channel.stats
        self._listener = socket.create_server((host, 0))
        self._listener.setblocking(False)
        self.host, self.port = self._listener.getsockname()[:2]
        self.url = f"socket://{self.host}:{self.port}"
        self._peer: dict[socket.socket, tuple[socket.socket, str, FrameSplitter]] = {}
        self._queue: list[tuple[float, int, socket.socket, bytes]] = []
        self._last: dict[socket.socket, float] = {}  # latest delivery time per destination (FIFO order)
        self._counter = itertools.count()
        self._stop = threading.Event()
        self._origin = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="radio-proxy", daemon=True)
        self._thread.start()

    @property
    def log(self) -> list[tuple[float, str, bool]] | None:
        """``None``, or a list to which every frame appends ``(wall time, "up"/"down", lost)``."""
        return self.channel.log

    @log.setter
    def log(self, value: list[tuple[float, str, bool]] | None) -> None:
        self.channel.log = value

    @property
    def drop_if(self) -> Callable[[str, bytes], bool] | None:
        """``None``, or ``f(direction, raw_frame) -> bool``: frames it returns True for are lost too."""
        return self.channel.drop_if

    @drop_if.setter
    def drop_if(self, value: Callable[[str, bytes], bool] | None) -> None:
        self.channel.drop_if = value

    # ------------------------------------------------------------ radio conditions
    def _route(self, unit: bytes, dest: socket.socket, direction: str, now: float) -> None:
        delay = self.channel.route(unit, direction, (now - self._origin) * self.speed, stamp=now)
        if delay is None:
            return
        due = now + delay / self.speed
        if not self.reorder:
            due = max(due, self._last.get(dest, 0.0))
            self._last[dest] = due
        heapq.heappush(self._queue, (due, next(self._counter), dest, unit))

    # ------------------------------------------------------------ loop
    def _accept(self) -> None:
        try:
            client, _ = self._listener.accept()
        except OSError:
            return
        try:
            upstream = socket.create_connection(self._upstream, timeout=2.0)
        except OSError:
            client.close()
            return
        for sock in (client, upstream):
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._peer[client] = (upstream, "up", FrameSplitter())
        self._peer[upstream] = (client, "down", FrameSplitter())

    def _drop(self, sock: socket.socket) -> None:
        other = self._peer.pop(sock, (None,))[0]
        for s in (sock, other):
            if s is not None:
                self._peer.pop(s, None)
                s.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            wait = _POLL if not self._queue else min(_POLL, max(0.0, self._queue[0][0] - time.monotonic()))
            try:
                ready, _, _ = select.select([self._listener, *self._peer], [], [], wait)
            except (OSError, ValueError):
                ready = []
            now = time.monotonic()
            for sock in ready:
                if sock is self._listener:
                    self._accept()
                    continue
                if sock not in self._peer:
                    continue
                try:
                    data = sock.recv(4096)
                except BlockingIOError:
                    continue
                except OSError:
                    data = b""
                if not data:
                    self._drop(sock)
                    continue
                dest, direction, splitter = self._peer[sock]
                for unit in splitter.feed(data):
                    self._route(unit, dest, direction, now)
            now = time.monotonic()
            while self._queue and self._queue[0][0] <= now:
                _, _, dest, unit = heapq.heappop(self._queue)
                try:
                    dest.setblocking(True)
                    dest.sendall(unit)
                    dest.setblocking(False)
                except OSError:
                    pass

    # ------------------------------------------------------------ life cycle
    def close(self) -> None:
        """Stop the proxy and close every connection (idempotent)."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        for sock in (*self._peer, self._listener):
            try:
                sock.close()
            except OSError:
                pass
        self._peer.clear()

    def __enter__(self) -> RadioProxy:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
