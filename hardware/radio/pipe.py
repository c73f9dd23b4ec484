"""An in-process byte stream between the PC's radio link and an emulated robot, driven by a clock.

:class:`StreamPair` is the radio of a lockstep emulation (:class:`pectoral_gym.hardware.clock.VirtualClock`): two
endpoints, ``pc`` (a serial-port look-alike for :class:`pectoral_gym.hardware.radio.link.RadioLink`) and ``robot``
(for :class:`pectoral_gym.hardware.emulator.EmulatedRobot`). Bytes written to one become readable at the other at
once, or, through a :class:`pectoral_gym.hardware.radio.channel.RadioChannel`, frame by frame after the channel's
seeded delay, unless it loses them. Waits count on the clock, so what arrives when depends on the program
and the seed alone, not on the operating system's scheduling.
"""

from __future__ import annotations

import heapq
import itertools

from pectoral_gym.hardware.clock import REAL_CLOCK, Clock
from pectoral_gym.hardware.radio.channel import RadioChannel
from pectoral_gym.hardware.radio.radioproxy import FrameSplitter

__all__ = ["StreamEnd", "StreamPair"]

_DEFAULT = object()  # read(): the end's own timeout


class StreamEnd:
    """One end of a :class:`StreamPair`: ``write``, ``read``, ``in_waiting``, ``close`` as a serial port has them.

    Attributes:
        timeout: Longest wait of :meth:`read` [clock s]; ``None``: until a byte arrives or the stream closes.
    """

    def __init__(self, pair: StreamPair, direction: str):
        self._pair, self._direction = pair, direction  # direction of the bytes this end writes
        self._clock = pair.clock
        self._inbox = self._clock.condition()
        self._buffer = bytearray()
        self._pending: list[tuple[float, int, bytes]] = []  # (due [clock s], order, unit) not yet arrived
        self._splitter = FrameSplitter()
        self._last_due = -float("inf")
        self.peer: StreamEnd | None = None
        self.timeout: float | None = None
        self.is_open = True

    # ------------------------------------------------------------ writing
    def write(self, data: bytes) -> int:
        """Send ``data`` to the other end (through the pair's channel, if any); returns ``len(data)``."""
        if not self.is_open:
            raise OSError("write to a closed stream")
        peer, channel = self.peer, self._pair.channel
        if peer is None or not peer.is_open:
            return len(data)  # nobody listens: the bytes go out into the air
        now = self._clock.monotonic()
        if channel is None:
            peer._arrive([(now, bytes(data))])
            return len(data)
        units = []
        for unit in self._splitter.feed(bytes(data)):
            delay = channel.route(unit, self._direction, now)
            if delay is None:
                continue
            due = now + delay
            if not channel.reorder:
                due = max(due, self._last_due)
                self._last_due = due
            units.append((due, unit))
        if units:
            peer._arrive(units)
        return len(data)

    def _arrive(self, units: list[tuple[float, bytes]]) -> None:
        with self._inbox:
            for due, unit in units:
                heapq.heappush(self._pending, (due, next(self._pair.order), unit))
            self._inbox.notify_all()

    # ------------------------------------------------------------ reading
    def _collect(self) -> float | None:
        """Move what has arrived by now into the buffer; returns the next arrival time (call with the lock)."""
        now = self._clock.monotonic()
        while self._pending and self._pending[0][0] <= now:
            self._buffer += heapq.heappop(self._pending)[2]
        return self._pending[0][0] if self._pending else None

    @property
    def in_waiting(self) -> int:
        """Bytes readable now."""
        with self._inbox:
            self._collect()
            return len(self._buffer)

    def read(self, size: int = 1, timeout: float | None | object = _DEFAULT) -> bytes:
        """Up to ``size`` bytes, waiting until at least one has arrived, ``timeout`` passed or the stream closed.

        Args:
            size: Most bytes returned.
            timeout: Longest wait [clock s] (default :attr:`timeout`; ``None``: no limit; ``0``: no wait).
        """
        limit = self.timeout if timeout is _DEFAULT else timeout
        end = None if limit is None else self._clock.monotonic() + limit
        with self._inbox:
            while True:
                arrival = self._collect()
                if self._buffer or not self.is_open:
                    break
                now = self._clock.monotonic()
                if end is not None and end <= now:
                    break
                wakes = [t for t in (arrival, end) if t is not None]
                self._inbox.wait(min(wakes) - now if wakes else None)
            out = bytes(self._buffer[:size])
            del self._buffer[:size]
            return out

    def close(self) -> None:
        """Close this end (idempotent); a reader waiting on it returns."""
        with self._inbox:
            self.is_open = False
            self._inbox.notify_all()


class StreamPair:
    """Two connected :class:`StreamEnd`: ``pc`` writes ``"up"`` to ``robot``, ``robot`` writes ``"down"`` to ``pc``.

    Args:
        clock: The clock the waits and the delays count on (a :class:`pectoral_gym.hardware.clock.VirtualClock` for
            lockstep).
        channel: Radio conditions (``None``: every byte arrives at once, none is lost).
    """

    def __init__(self, clock: Clock = REAL_CLOCK, channel: RadioChannel | None = None):
        self.clock, self.channel = clock, channel
        self.order = itertools.count()
        self.pc, self.robot = StreamEnd(self, "up"), StreamEnd(self, "down")
        self.pc.peer, self.robot.peer = self.robot, self.pc

    def close(self) -> None:
        """Close both ends."""
        self.pc.close()
        self.robot.close()
