"""PC side of the radio link: :class:`RadioLink` over any ``serial.serial_for_url`` URL.

``/dev/ttyUSB0`` (the XBee on USB), ``socket://host:port`` (an emulator process) and ``loop://``
(tests) all work. A reader thread decodes the robot's STATUS messages; a keep-alive thread re-sends
a *copy* of the current fin command (same command identity, so it never extends the command's lease;
``docs/protocol.md``) every ``keepalive_period`` until the lease ends, then STOP; HEARTBEAT when
stopped. It retries an unacknowledged SET_FINS/STOP after ``ack_timeout``, at most ``max_retries`` times
(same frame, same sequence number). Only :meth:`RadioLink.set_fins` starts a new lease.
:meth:`RadioLink.emergency_stop` takes no lock (for signal handlers). ``close()`` sends STOP and is
idempotent.
"""

from __future__ import annotations

import secrets
import threading
import time
import warnings
from dataclasses import dataclass

import numpy as np
import serial

from hardware import protocol as pr

__all__ = ["RadioLink", "LinkStats"]


@dataclass
class LinkStats:
    """Counters of a :class:`RadioLink` (cumulative).

    Attributes:
        sent: Messages written (incl. keep-alives and retries).
        received: Valid STATUS messages from the robot with a new sequence number.
        acked: Commands acknowledged.
        retries: Re-transmissions of an unacknowledged command.
        unacked: Commands given up after ``max_retries``.
        dropped: Robot messages missing from its sequence (gaps).
        duplicates: Robot messages received twice.
        stale: Robot messages older than one already received (reordered).
        crc_errors: Frames with a good XBee checksum but a bad CRC-16.
        checksum_errors: Frames with a bad XBee checksum.
        framing_errors: Bad lengths and abandoned frames.
        write_errors: Failed writes to the port.
    """

    sent: int = 0
    received: int = 0
    acked: int = 0
    retries: int = 0
    unacked: int = 0
    dropped: int = 0
    duplicates: int = 0
    stale: int = 0
    crc_errors: int = 0
    checksum_errors: int = 0
    framing_errors: int = 0
    write_errors: int = 0


class RadioLink:
    """Talks to the fish's firmware through an XBee (or anything that carries the same bytes).

    Args:
        port: A ``serial.serial_for_url`` URL, or an already open serial-like object.
        baudrate: Serial speed (ignored by ``socket://`` and ``loop://``).
        dest64: 64-bit address of the robot's XBee (default broadcast; set it for unicast with MAC retries).
        keepalive_period: Re-send the current command (or a HEARTBEAT) this often [s]; must be well below
            the firmware watchdog (0.5 s by default).
        ack_timeout: Retry an unacknowledged SET_FINS/STOP after this long [s].
        max_retries: Retries per command before it counts as ``unacked``.
        session: 32-bit session (default from :mod:`secrets`, never from a seeded generator): the robot
            serves the newest session and ignores retired ones, so a restarted PC gets a fresh one.
    """

    def __init__(self, port: str | serial.SerialBase, baudrate: int = 57600, dest64: int = pr.BROADCAST,
                 keepalive_period: float = 0.1, ack_timeout: float = 0.05, max_retries: int = 3,
                 session: int | None = None):
        if not keepalive_period > 0 or not ack_timeout > 0 or int(max_retries) < 0:
            raise ValueError("keepalive_period and ack_timeout must be > 0 s and max_retries >= 0")
        self.serial = serial.serial_for_url(port, baudrate=baudrate, timeout=0.01) if isinstance(port, str) else port
        if isinstance(port, str) and "://" not in port and int(dest64) == pr.BROADCAST:
            warnings.warn("RadioLink: commands are broadcast, so every robot on this radio channel obeys them; "
                          "pass dest64=<the robot XBee's 64-bit address>", stacklevel=2)
        self.dest64 = int(dest64)
        self.keepalive_period = float(keepalive_period)
        self.ack_timeout = float(ack_timeout)
        self.max_retries = int(max_retries)
        self.lease_scale = 1.0  # wall seconds per robot second (1 / speed of an accelerated emulator)
        self.session = secrets.randbits(32) if session is None else int(session) & 0xFFFFFFFF
        self.stats = LinkStats()
        self.decoder = pr.StreamDecoder()
        self.tracker = pr.SequenceTracker()
        self.last_status: pr.Status | None = None
        self.last_status_time: float | None = None  # time.monotonic() of the newest STATUS
        self.command: np.ndarray | None = None  # (2, 4) current fin command, None when stopped
        self.lease_end = -float("inf")  # time.monotonic() after which the robot no longer runs the command
        self._command_id = 0
        self._lease = pr.DEFAULT_LEASE
        self._emergency: int | None = None  # seq of a STOP sent by emergency_stop(), for the link thread
        self._seq = 0
        self._pending: tuple[int, bytes, float, int, pr.MsgType] | None = None  # seq, frame, deadline, tries, type
        self._acked: set[int] = set()
        self._lock = threading.RLock()
        self._write_lock = threading.Lock()
        self._acked_event = threading.Condition(self._lock)
        self._closed = False
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._read_loop, name="radio-read", daemon=True),
                         threading.Thread(target=self._keepalive_loop, name="radio-keepalive", daemon=True)]
        for thread in self._threads:
            thread.start()

    # ------------------------------------------------------------ sending
    def _next(self, mtype: pr.MsgType, fins: tuple[float, ...] | None = None) -> tuple[int, bytes]:
        if self._emergency is not None:  # move past the sequence number emergency_stop() used
            self._seq, self._emergency = self._emergency, None
        self._seq = (self._seq + 1) & 0xFFFF
        msg = pr.Message(mtype, self._seq, self.session, fins=fins, command=self._command_id, lease=self._lease)
        return self._seq, pr.encode_frame(pr.tx_request(pr.encode_message(msg), self.dest64))

    def _write(self, frame: bytes) -> None:
        with self._write_lock:
            try:
                self.serial.write(frame)
                self.stats.sent += 1
            except (serial.SerialException, OSError):
                self.stats.write_errors += 1

    def _send_tracked(self, mtype: pr.MsgType, fins: tuple[float, ...] | None) -> int:
        with self._lock:
            seq, frame = self._next(mtype, fins)
            self._pending = (seq, frame, time.monotonic() + self.ack_timeout, 0, mtype)
            self._write(frame)  # under the lock: frames leave in sequence order
        return seq

    def emergency_stop(self) -> None:
        """Send STOP without taking any lock (safe in a signal handler, even one that interrupted this link).

        The frame jumps the sequence by 64 so the robot takes it as new whatever was in flight; the link
        thread then moves its own counter past it. Interleaved bytes cannot corrupt it: the robot's
        decoder resynchronises on the start delimiter and drops the interrupted frame. The lease is the
        backstop if even this write fails.
        """
        self.command = None
        seq = (self._seq + 64) & 0xFFFF
        msg = pr.Message(pr.MsgType.STOP, seq, self.session)
        try:
            self.serial.write(pr.encode_frame(pr.tx_request(pr.encode_message(msg), self.dest64)))
        except Exception:  # noqa: BLE001 - a signal handler must not raise; the lease stops the fins anyway
            pass
        self._emergency = seq

    def set_fins(self, beats: np.ndarray, lease: float = pr.DEFAULT_LEASE) -> int:
        """Command both fins ``(2, 4)`` (right first; bias, amplitude [rad], period [s], ratio); returns the seq.

        A new command identity with a lease of ``lease`` robot seconds (``(0, MAX_LEASE]``): the robot
        stops the fins when it runs out unless another ``set_fins`` comes first. Nothing is checked here
        beyond finiteness and the wire range: clip with :mod:`hardware.safety` first.
        """
        if self._closed:
            raise RuntimeError("the radio link is closed")
        b = np.asarray(beats, dtype=float).reshape(2, 4)
        if not np.all(np.isfinite(b)):
            raise ValueError(f"fin command must be finite, got {b.tolist()}")
        fins = tuple(b.ravel().tolist())
        # wire-range and lease checks before any state
        pr.encode_message(pr.Message(pr.MsgType.SET_FINS, 0, fins=fins, lease=lease))
        with self._lock:
            self.command = b.copy()
            self._command_id = (self._command_id + 1) & 0xFFFF
            self._lease = float(lease)
            self.lease_end = time.monotonic() + self._lease * self.lease_scale  # the robot counts from receipt
            return self._send_tracked(pr.MsgType.SET_FINS, fins)

    def stop(self, wait: float = 0.0) -> bool:
        """Send STOP (retried like a command); with ``wait`` > 0 block up to ``wait`` s for the ack."""
        with self._lock:
            self.command = None
            self.lease_end = -float("inf")
        if self._closed:
            return False
        seq = self._send_tracked(pr.MsgType.STOP, None)
        return self.wait_ack(seq, wait) if wait > 0 else False

    def wait_ack(self, seq: int, timeout: float) -> bool:
        """Block until message ``seq`` is acknowledged or ``timeout`` s pass; returns whether it was."""
        deadline = time.monotonic() + timeout
        with self._acked_event:
            while seq not in self._acked:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._acked_event.wait(remaining)
            return True

    def _keepalive_loop(self) -> None:
        next_keepalive = time.monotonic() + self.keepalive_period
        while not self._stop.wait(min(self.ack_timeout, self.keepalive_period) / 4):
            retry = None
            with self._lock:
                now = time.monotonic()  # after the lock: a stalled thread must not act on an old clock
                if self._pending is not None and now >= self._pending[2]:
                    seq, frame, _, tries, mtype = self._pending
                    if tries < self.max_retries:
                        self._pending = (seq, frame, now + self.ack_timeout, tries + 1, mtype)
                        self.stats.retries += 1
                        retry = frame
                    else:
                        self._pending = None
                        self.stats.unacked += 1
                if self.command is not None and now >= self.lease_end:
                    self.command = None  # the lease ran out (a paused controller, or a stalled process)
                    next_keepalive = now
                keepalive = None
                if now >= next_keepalive:
                    next_keepalive = now + self.keepalive_period
                    if self.command is not None:  # a copy: same command identity, no new lease
                        _, keepalive = self._next(pr.MsgType.SET_FINS, tuple(self.command.ravel().tolist()))
                    elif self.last_status is None or self.last_status.state == pr.RobotState.RUNNING:
                        _, keepalive = self._next(pr.MsgType.STOP)  # not known to be still: repeat the stop
                    else:
                        _, keepalive = self._next(pr.MsgType.HEARTBEAT)
                for frame in (retry, keepalive):
                    if frame is not None:
                        self._write(frame)

    # ------------------------------------------------------------ receiving
    def _read_loop(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.serial.read(max(1, self.serial.in_waiting))
            except (serial.SerialException, OSError, TypeError, AttributeError):
                if self._stop.is_set():
                    return
                time.sleep(0.01)
                continue
            if data:
                self._receive(data)

    def _receive(self, data: bytes) -> None:
        messages = self.decoder.feed(data)
        with self._lock:
            d = self.decoder
            self.stats.crc_errors, self.stats.checksum_errors = d.crc_errors, d.checksum_errors
            self.stats.framing_errors = d.framing_errors + d.truncated
            for msg in messages:
                if msg.type != pr.MsgType.STATUS:
                    continue  # our own frames echoed (loop://) or a confused peer
                verdict = self.tracker.check(msg.seq, msg.session)
                self.stats.duplicates, self.stats.stale = self.tracker.duplicates, self.tracker.stale
                self.stats.dropped = self.tracker.lost
                if verdict != pr.Verdict.NEW:
                    continue
                self.stats.received += 1
                self.last_status, self.last_status_time = msg.status, time.monotonic()
                ack = msg.status.ack_seq
                if self._pending is not None and self._satisfies(msg.status, self._pending):
                    self._pending = None
                    self.stats.acked += 1
                self._acked.add(ack)
                if len(self._acked) > 1024:
                    self._acked = {ack}
                self._acked_event.notify_all()

    @staticmethod
    def _satisfies(status: pr.Status, pending: tuple) -> bool:
        """Whether ``status`` settles the pending command.

        Its own ack does, and so does the ack of a later keep-alive that repeats it (the keep-alive always
        carries the current command; after a STOP the robot must also report that it is not running).
        """
        seq, mtype = pending[0], pending[4]
        if status.ack_seq == seq:
            return True
        newer = 0 < ((status.ack_seq - seq) & 0xFFFF) < 0x8000
        return newer and (mtype == pr.MsgType.SET_FINS or status.state != pr.RobotState.RUNNING)

    # ------------------------------------------------------------ health and life cycle
    def status_age(self) -> float:
        """Seconds since the last STATUS from the robot (``inf`` if none yet)."""
        t = self.last_status_time
        return float("inf") if t is None else time.monotonic() - t

    def health(self) -> dict[str, float | int | str | None]:
        """Counters and the robot's last reported state, for ``info`` and logs."""
        with self._lock:
            out: dict[str, float | int | str | None] = dict(vars(self.stats))
            status = self.last_status
        out["status_age"] = self.status_age()
        out["robot_state"] = None if status is None else pr.state_name(status.state)
        return out

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return self._closed

    def close(self, stop_wait: float = 0.2) -> None:
        """Send STOP (waiting up to ``stop_wait`` s for its ack), stop the threads, close the port. Idempotent."""
        if self._closed:
            return
        try:
            self.stop(wait=stop_wait)
        finally:
            self._closed = True
            self._stop.set()
            for thread in self._threads:
                thread.join(timeout=1.0)
            try:
                self.serial.close()
            except (serial.SerialException, OSError):
                pass

    def __enter__(self) -> RadioLink:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
