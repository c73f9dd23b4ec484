"""PC side of the radio link: :class:`RadioLink` over any ``serial.serial_for_url`` URL.

``/dev/ttyUSB0`` (the XBee on USB), ``socket://host:port`` (an emulator process) and ``loop://``
(tests) all work. A reader thread decodes the robot's STATUS messages; a keep-alive thread re-sends
a *copy* of the current fin command (same command identity and deadline, so it never extends the
command; ``docs/protocol.md``) every ``keepalive_period`` until the lease ends, then STOP; HEARTBEAT when
stopped. It retries an unacknowledged SET_FINS/STOP after a timeout that adapts to the measured round
trip (:class:`pectoral_gym.hardware.radio.linkclock.RttEstimator`), at most ``max_retries`` times (same frame, same
sequence number). Only :meth:`RadioLink.set_fins` starts a new lease; it also carries a deadline on the robot's
clock (:class:`pectoral_gym.hardware.radio.linkclock.RobotClock`), so no copy runs past the lease counted from the call.

Control (protocol version 3): every STATUS names the session it answers and the session the robot
serves. :attr:`RadioLink.control_lost` latches why this PC is not (or no longer) the robot's controller:
``"taken_over"``, ``"robot_busy"`` or ``"robot_rebooted"`` (cleared by :meth:`RadioLink.resync`). Under the first
two (:attr:`RadioLink.displaced`) the link falls silent: only the operator's own stop is still sent.
:meth:`RadioLink.emergency_stop` takes no lock (for signal handlers). ``close()`` sends STOP and is
idempotent.
"""

from __future__ import annotations

import secrets
import threading
import warnings
from collections import deque

import numpy as np
import serial

from pectoral_gym.hardware.clock import REAL_CLOCK, Clock
from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio import xbee as xb
from pectoral_gym.hardware.radio.linkclock import CLOCK_TOLERANCE, RobotClock, RttEstimator
from pectoral_gym.hardware.radio.linkstatus import LinkStats, StatusReceiver

__all__ = ["RadioLink", "LinkStats", "DEADLINE_HORIZON", "DISPLACED", "DisplacedError"]

# control_lost reasons under which another session is served: this PC must not send (RadioLink.displaced).
DISPLACED = ("taken_over", "robot_busy")


class DisplacedError(RuntimeError):
    """The robot serves another session (``reason``: ``"taken_over"`` or ``"robot_busy"``): this run must end."""

    def __init__(self, reason: str, message: str):
        super().__init__(message)
        self.reason = reason

# Every command's deadline: this long after set_fins() [robot s], on a lower bound of the robot's clock, so no
# copy runs later than that after the call, on any radio. The lease (from the robot's receipt) ends it
# earlier when the first copy arrives in time. Below the 1.0 s target by one 10 ms firmware tick and margin;
# the lower bound runs behind the robot's clock by the STATUS's return latency, so a longer horizon than the
# lease keeps the fins going between steps at 100-300 ms latency (docs/protocol.md, "Deadline").
DEADLINE_HORIZON = 0.95


class RadioLink(StatusReceiver):
    """Talks to the fish's firmware through an XBee (or anything that carries the same bytes).

    Args:
        port: A ``serial.serial_for_url`` URL, or an already open serial-like object.
        baudrate: Serial speed (ignored by ``socket://`` and ``loop://``).
        dest64: 64-bit address of the robot's XBee (default broadcast; set it for unicast with MAC retries).
        keepalive_period: Re-send the current command (or a HEARTBEAT) this often [s]; must be well below
            the firmware watchdog (0.5 s by default).
        ack_timeout: First and smallest retry timeout of an unacknowledged SET_FINS/STOP [s]; the timeout
            then follows the measured round trip (``SRTT + 4 RTTVAR``, at most ``max_ack_timeout``).
        max_retries: Retries per command before it counts as ``unacked``.
        session: 32-bit session (default from :mod:`secrets`, never from a seeded generator): a restarted
            PC gets a fresh one.
        take_over: Take the robot over even if another live session controls it (sends CLAIM): an explicit
            operator action. Without it, a robot serving another live session refuses this PC
            (``control_lost == "robot_busy"``).
        max_ack_timeout: Largest retry timeout [s].
        clock_tolerance: Largest relative rate error of the robot's clock (:class:`RobotClock`).
        clock: The PC's clock (:mod:`pectoral_gym.hardware.clock`): every time, wait and thread of the link.

    Attributes:
        robot_clock: A lower bound of the robot's clock (:class:`RobotClock`), from its STATUS messages.
        lease_scale: Wall seconds per robot second (``1 / speed`` of an accelerated emulator).
        deadline_horizon: A command's deadline, in robot seconds after :meth:`set_fins` [s]
            (:data:`DEADLINE_HORIZON`).
        control_lost: ``""`` while this PC may control the robot, else why not (latched).
        served: The session the robot last said it serves (``None`` before any STATUS; 0: none).
        boot: The robot's boot id from its STATUS (``None`` before any).
    """

    def __init__(self, port: str | serial.SerialBase, baudrate: int = 57600, dest64: int = xb.BROADCAST,
                 keepalive_period: float = 0.1, ack_timeout: float = 0.05, max_retries: int = 3,
                 session: int | None = None, take_over: bool = False, max_ack_timeout: float = 1.0,
                 clock_tolerance: float = CLOCK_TOLERANCE, clock: Clock = REAL_CLOCK):
        if not keepalive_period > 0 or not ack_timeout > 0 or int(max_retries) < 0:
            raise ValueError("keepalive_period and ack_timeout must be > 0 s and max_retries >= 0")
        if not max_ack_timeout >= ack_timeout:
            raise ValueError(f"max_ack_timeout must be >= ack_timeout, got {max_ack_timeout!r} < {ack_timeout!r}")
        self.serial = serial.serial_for_url(port, baudrate=baudrate, timeout=0.01) if isinstance(port, str) else port
        if isinstance(port, str) and "://" not in port and int(dest64) == xb.BROADCAST:
            warnings.warn("RadioLink: commands are broadcast, so every robot on this radio channel obeys them; "
                          "pass dest64=<the robot XBee's 64-bit address>", stacklevel=2)
        self.dest64 = int(dest64)
        self.clock = clock
        self.keepalive_period = float(keepalive_period)
        self.ack_timeout = float(ack_timeout)
        self.max_retries = int(max_retries)
        self.lease_scale = 1.0  # wall seconds per robot second (1 / speed of an accelerated emulator)
        self.deadline_horizon = DEADLINE_HORIZON
        self.session = secrets.randbits(32) if session is None else int(session) & 0xFFFFFFFF
        self.take_over = bool(take_over)
        self.control_lost = ""
        self.served: int | None = None
        self.boot: int | None = None
        self._served = False  # the robot answered one of our messages as our controller (this boot)
        self.rtt_estimator = RttEstimator(self.ack_timeout, self.ack_timeout, float(max_ack_timeout))
        self.robot_clock = RobotClock(clock_tolerance)
        self._sent_at: dict[int, tuple[float, bool]] = {}  # seq -> (send time, re-sent), for RTT samples
        self._deadline = (0, 0)  # (deadline, boot) of the current command
        self._commanded = False  # fins of ours may run: repeat STOP until the robot reports still
        self._quiet: int | None = None  # newest seq of ours answered with the robot not RUNNING
        self._old_boots: deque[int] = deque(maxlen=8)  # boots before a reboot: their late STATUS is stale
        self.stats = LinkStats()
        self.decoder = pr.StreamDecoder()
        self.tracker = pr.SequenceTracker()
        self.latch_tracker = pr.SequenceTracker()  # LATCH reports are numbered on their own, keyed by boot
        self.latch_reports: deque[tuple[float, pr.Latch]] = deque(maxlen=1024)  # until drain_latches()
        self.last_status: pr.Status | None = None
        self.last_status_time: float | None = None  # clock.monotonic() of the newest STATUS
        self.command: np.ndarray | None = None  # (2, 4) current fin command, None when stopped
        self.lease_end = -float("inf")  # clock.monotonic() after which the robot no longer runs the command
        self._command_id = 0
        self._lease = pr.DEFAULT_LEASE
        self._emergency: int | None = None  # seq of a STOP sent by emergency_stop(), for the link thread
        self._seq = 0
        self._pending: tuple[int, bytes, float, int, pr.MsgType] | None = None  # seq, frame, deadline, tries, type
        self._acked: set[int] = set()
        # (clock.monotonic(), ack_seq) of every STATUS to us, in arrival order: when a command was surely received
        self.ack_log: deque[tuple[float, int]] = deque(maxlen=512)
        self._lock = threading.RLock()
        self._write_lock = threading.Lock()
        self._acked_event = clock.condition(self._lock)
        self._closed = False
        self._stop = clock.event()
        self._threads = [clock.thread(self._read_loop, "radio-read"),
                         clock.thread(self._keepalive_loop, "radio-keepalive")]
        for thread in self._threads:
            thread.start()

    # ------------------------------------------------------------ sending
    def _next(self, mtype: pr.MsgType, fins: tuple[float, ...] | None = None) -> tuple[int, bytes]:
        if self._emergency is not None:  # move past the sequence number emergency_stop() used
            self._seq, self._emergency = self._emergency, None
        self._seq = (self._seq + 1) & 0xFFFF
        deadline, boot = self._deadline
        msg = pr.Message(mtype, self._seq, self.session, fins=fins, command=self._command_id, lease=self._lease,
                         deadline=deadline, boot=boot)
        self._sent_at[self._seq] = (self.clock.monotonic(), False)
        if len(self._sent_at) > 256:
            self._sent_at.pop(next(iter(self._sent_at)))
        return self._seq, xb.encode_frame(xb.tx_request(pr.encode_message(msg), self.dest64))

    def _write(self, frame: bytes) -> None:
        with self._write_lock:
            try:
                self.serial.write(frame)
                self.stats.sent += 1
            except (serial.SerialException, OSError):
                self.stats.write_errors += 1

    def _send_tracked(self, mtype: pr.MsgType, fins: tuple[float, ...] | None) -> int:
        with self._lock:
            if self.take_over and not self._served and not self.control_lost:
                self._write(self._next(pr.MsgType.CLAIM)[1])  # the operator's takeover goes first
            seq, frame = self._next(mtype, fins)
            self._pending = (seq, frame, self.clock.monotonic() + self.rtt_estimator.timeout(), 0, mtype)
            self._write(frame)  # under the lock: frames leave in sequence order
        return seq

    def emergency_stop(self) -> None:
        """Send STOP without taking any lock (safe in a signal handler, even one that interrupted this link).

        The frame jumps the sequence by 64 so the robot takes it as new whatever was in flight; the link
        thread then moves its own counter past it. Interleaved bytes cannot corrupt it: the robot's
        decoder resynchronises on the start delimiter and drops the interrupted frame. The lease is the
        backstop if even this write fails. A STOP needs no authority: the robot halts whoever it serves.
        """
        self.command = None
        seq = (self._seq + 64) & 0xFFFF
        msg = pr.Message(pr.MsgType.STOP, seq, self.session)
        try:
            self.serial.write(xb.encode_frame(xb.tx_request(pr.encode_message(msg), self.dest64)))
        except Exception:  # noqa: BLE001 - a signal handler must not raise; the lease stops the fins anyway
            pass
        self._emergency = seq

    def set_fins(self, beats: np.ndarray, lease: float = pr.DEFAULT_LEASE) -> int:
        """Command both fins ``(2, 4)`` (right first; bias, amplitude [rad], period [s], ratio); returns the seq.

        A new command identity with a lease of ``lease`` robot seconds (``(0, MAX_LEASE]``): the robot
        runs it for at most ``lease`` after its receipt. Once the link has heard the robot's clock (any
        STATUS), the command also carries a deadline on the robot's clock, a lower bound of the robot's
        time ``deadline_horizon`` robot seconds after this call, so no copy of it, however late, runs
        past that; the PC's own keep-alive copies stop ``lease`` after this call. Nothing is checked
        here beyond finiteness and the wire range: clip with :mod:`pectoral_gym.hardware.safety.rules` first. While
        :attr:`control_lost` is set nothing is sent (the command is counted in ``stats.suppressed``) and
        ``-1`` is returned.
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
            if self.control_lost:
                self.stats.suppressed += 1
                self.command = None
                return -1
            now = self.clock.monotonic()
            self.command = b.copy()
            self._command_id = (self._command_id + 1) & 0xFFFF
            self._lease = float(lease)
            self.lease_end = now + self._lease * self.lease_scale
            horizon = now + self.deadline_horizon * self.lease_scale
            deadline = self.robot_clock.deadline_ms(horizon, 1.0 / self.lease_scale)
            self._deadline = (deadline, self.robot_clock.boot or 0) if deadline else (0, 0)
            self._commanded = True
            return self._send_tracked(pr.MsgType.SET_FINS, fins)

    def stop(self, wait: float = 0.0, operator: bool = False) -> bool:
        """Send STOP (retried like a command); with ``wait`` > 0 block up to ``wait`` s for the robot's word.

        Returns True only once a STATUS addressed to this session reports the robot not RUNNING after
        this STOP (always False with ``wait = 0``). A STOP needs no authority: it halts the fins whoever
        the robot serves. So once this PC knows another session is served (:attr:`displaced`) it sends
        none, unless ``operator`` (the operator's own stop, as :meth:`emergency_stop`): the takeover
        already halted our fins (``docs/protocol.md`` §5), and any further STOP could only halt the new
        controller's. Returns False then.
        """
        with self._lock:
            self.command = None
            self.lease_end = -float("inf")
            if self.displaced and not operator:
                self.stats.suppressed += 1
                return False
        if self._closed:
            return False
        seq = self._send_tracked(pr.MsgType.STOP, None)
        return self.wait_still(seq, wait) if wait > 0 else False

    def wait_ack(self, seq: int, timeout: float) -> bool:
        """Block until message ``seq`` is acknowledged (by a STATUS addressed to us) or ``timeout`` s pass."""
        deadline = self.clock.monotonic() + timeout
        with self._acked_event:
            while seq not in self._acked:
                remaining = deadline - self.clock.monotonic()
                if remaining <= 0:
                    return False
                self._acked_event.wait(remaining)
            return True

    def wait_still(self, seq: int, timeout: float) -> bool:
        """Block until a STATUS to us answering ``seq`` or a later message reports the robot not RUNNING."""
        deadline = self.clock.monotonic() + timeout
        with self._acked_event:
            while self._quiet is None or not (self._quiet == seq or pr.serial_newer(self._quiet, seq)):
                remaining = deadline - self.clock.monotonic()
                if remaining <= 0:
                    return False
                self._acked_event.wait(remaining)
            return True

    def _keepalive_message(self) -> pr.MsgType | None:
        """What the keep-alive sends now when no command runs (call with the lock held)."""
        if self.displaced:
            return None  # silent: never hold the robot for nobody, never keep another PC out
        if self.take_over and not self._served and not self.control_lost:
            return pr.MsgType.CLAIM
        status = self.last_status
        if self._commanded and (status is None or status.state == pr.RobotState.RUNNING):
            return pr.MsgType.STOP  # our fins may still run: repeat the stop
        return pr.MsgType.HEARTBEAT

    def _keepalive_loop(self) -> None:
        next_keepalive = self.clock.monotonic() + self.keepalive_period
        while not self._stop.wait(min(self.ack_timeout, self.keepalive_period) / 4):
            retry = None
            with self._lock:
                now = self.clock.monotonic()  # after the lock: a stalled thread must not act on an old clock
                if self._pending is not None and now >= self._pending[2]:
                    seq, frame, _, tries, mtype = self._pending
                    if tries < self.max_retries:
                        backoff = min(self.rtt_estimator.timeout() * 2 ** (tries + 1), self.rtt_estimator.high)
                        self._pending = (seq, frame, now + backoff, tries + 1, mtype)
                        self._sent_at[seq] = (self._sent_at.get(seq, (now, True))[0], True)  # Karn: no sample
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
                    if self.command is not None:  # a copy: same command identity and deadline, no new lease
                        _, keepalive = self._next(pr.MsgType.SET_FINS, tuple(self.command.ravel().tolist()))
                    else:
                        mtype = self._keepalive_message()
                        keepalive = None if mtype is None else self._next(mtype)[1]
                for frame in (retry, keepalive):
                    if frame is not None:
                        self._write(frame)

    # ------------------------------------------------------------ receiving: StatusReceiver (.linkstatus)
    # ------------------------------------------------------------ control
    def resync(self, wait: float = 0.0) -> bool:
        """Clear ``control_lost == "robot_rebooted"`` (and only that) once the link is re-synchronised.

        Re-synchronised: the rebooted robot answers this session as the one it serves, and its new clock
        is known (the keep-alive's HEARTBEAT takes the robot, which serves nobody after a power-up).
        Blocks up to ``wait`` s for it. Returns whether :attr:`control_lost` is empty afterwards.
        """
        deadline = self.clock.monotonic() + wait
        with self._acked_event:
            while True:
                if self.control_lost == "robot_rebooted" and self._served and self.robot_clock.synced:
                    self.control_lost = ""
                if self.control_lost != "robot_rebooted":
                    return not self.control_lost
                remaining = deadline - self.clock.monotonic()
                if remaining <= 0:
                    return False
                self._acked_event.wait(remaining)

    def rtt(self) -> float | None:
        """Smoothed round trip [wall s] of messages answered at the first try (``None`` before any)."""
        return self.rtt_estimator.srtt

    # ------------------------------------------------------------ health and life cycle
    def status_age(self) -> float:
        """Seconds since the last STATUS addressed to this session (``inf`` if none yet)."""
        t = self.last_status_time
        return float("inf") if t is None else self.clock.monotonic() - t

    def health(self) -> dict[str, float | int | str | None]:
        """Counters and the robot's last reported state, for ``info`` and logs."""
        with self._lock:
            out: dict[str, float | int | str | None] = dict(vars(self.stats))
            status = self.last_status
        out["status_age"] = self.status_age()
        out["robot_state"] = None if status is None else pr.state_name(status.state)
        out["control_lost"] = self.control_lost
        out["rtt"] = self.rtt()
        out["ack_timeout"] = self.rtt_estimator.timeout()
        out["served_session"] = self.served
        out["robot_boot"] = self.boot
        return out

    @property
    def displaced(self) -> bool:
        """Whether the robot is known to serve another session (``control_lost`` ``taken_over`` or ``robot_busy``).

        A displaced link sends nothing of its own accord (no command, keep-alive, retry or STOP): only the
        operator's stop (:meth:`emergency_stop`, ``stop(operator=True)``) still goes out.
        """
        return self.control_lost in DISPLACED

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return self._closed

    def close(self, stop_wait: float = 0.2) -> None:
        """Send STOP (waiting up to ``stop_wait`` s for its ack), stop the threads, close the port. Idempotent.

        No STOP when :attr:`displaced` (:meth:`stop`).
        """
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
