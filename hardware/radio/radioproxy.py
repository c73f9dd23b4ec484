"""Lossy radio between a :class:`~pectoral_gym.hardware.radio.link.RadioLink` and a robot: delay, jitter, loss, bursts.

:class:`RadioProxy` listens on ``socket://127.0.0.1:PORT`` (its :attr:`~RadioProxy.url`); every
connection to it gets its own connection to ``upstream_url`` (an emulated robot's ``socket://`` URL),
and bytes flow both ways through it. It is frame-aware: it cuts each direction's byte stream into
XBee API frames (start delimiter ``0x7E``, escaped length; ``pectoral_gym.hardware.radio.protocol``) and delays or drops
*whole* frames, so a loss is a lost message, never a damaged stream. Bytes outside any frame are
passed on with the same delay.

Radio conditions, all in *robot* seconds (divided by ``speed`` on the wall clock, for an emulator
running ``speed`` times faster):

* ``latency`` ``(lo, hi)``: each frame is delayed by a uniform draw from ``[lo, hi]`` (one-way). By
  default frames of one direction keep their order (a serial radio: a late frame holds up the ones
  behind it); ``reorder=True`` lets a later frame overtake a slower one.
* ``loss``: each frame is lost independently with this probability.
* ``burst`` ``(fraction, length)``: fades of ``length`` seconds cover ``fraction`` of the time (gaps
  between fades exponential with mean ``length (1 - fraction) / fraction``); every frame that would be
  *sent* during a fade is lost, in both directions.

Every draw comes from one generator seeded with ``seed``, so the sequence of losses, delays and fades is
the same from run to run (the wall-clock timing of the threads around it is not).
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
from dataclasses import dataclass

import numpy as np

from pectoral_gym.hardware.radio.xbee import ESCAPE, START

__all__ = ["RadioProxy", "FrameSplitter", "ProxyStats"]

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


@dataclass
class ProxyStats:
    """Frames through a :class:`RadioProxy` (cumulative); ``up`` is PC -> robot, ``down`` robot -> PC.

    Attributes:
        up_sent: Frames delivered to the robot.
        up_lost: Frames to the robot lost (at random or in a fade).
        down_sent: Frames delivered to the PC.
        down_lost: Frames to the PC lost.
        fades: Fades begun so far.
    """

    up_sent: int = 0
    up_lost: int = 0
    down_sent: int = 0
    down_lost: int = 0
    fades: int = 0


def _pair(value: float | tuple[float, float], name: str) -> tuple[float, float]:
    lo, hi = (value, value) if isinstance(value, (int, float)) else (float(value[0]), float(value[1]))
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo <= hi):
        raise ValueError(f"RadioProxy: {name} must be s or (lo, hi) s with 0 <= lo <= hi, got {value!r}")
    return float(lo), float(hi)


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
        self.latency = _pair(latency, "latency")
        if not 0.0 <= loss < 1.0:
            raise ValueError(f"RadioProxy: loss must be in [0, 1), got {loss!r}")
        if burst is not None and not (0.0 <= burst[0] < 1.0 and math.isfinite(burst[1]) and burst[1] > 0):
            raise ValueError(f"RadioProxy: burst must be (fraction in [0, 1), length > 0 s), got {burst!r}")
        if not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"RadioProxy: speed must be a finite number > 0, got {speed!r}")
        self.loss, self.burst, self.speed, self.reorder = float(loss), burst, float(speed), bool(reorder)
        self.stats = ProxyStats()
        self.log: list[tuple[float, str, bool]] | None = None
        self.drop_if: Callable[[str, bytes], bool] | None = None
        self._rng = np.random.default_rng(seed)
        self._fade = (math.inf, math.inf)  # (start, end) of the current or next fade [robot s since start]
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
        if burst is not None and burst[0] > 0:
            self._fade = self._next_fade(0.0)
        self._thread = threading.Thread(target=self._run, name="radio-proxy", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------ radio conditions
    def _next_fade(self, after: float) -> tuple[float, float]:
        fraction, length = self.burst
        start = after + float(self._rng.exponential(length * (1.0 - fraction) / fraction))
        return start, start + length

    def _in_fade(self, t: float) -> bool:
        """Whether robot time ``t`` (non-decreasing between calls) falls in a fade."""
        while t >= self._fade[1]:
            self._fade = self._next_fade(self._fade[1])
            self.stats.fades += 1
        return self._fade[0] <= t

    def _route(self, unit: bytes, dest: socket.socket, direction: str, now: float) -> None:
        t = (now - self._origin) * self.speed
        is_frame = unit[:1] == bytes((START,))
        lost = is_frame and (self._in_fade(t) or (self.loss > 0 and self._rng.random() < self.loss))
        if is_frame and not lost and self.drop_if is not None:
            lost = bool(self.drop_if(direction, unit))
        delay = float(self._rng.uniform(*self.latency)) / self.speed
        if self.log is not None and is_frame:
            self.log.append((now, direction, bool(lost)))
        if is_frame:
            name = f"{direction}_{'lost' if lost else 'sent'}"
            setattr(self.stats, name, getattr(self.stats, name) + 1)
        if lost:
            return
        due = now + delay
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
