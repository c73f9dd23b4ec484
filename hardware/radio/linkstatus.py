"""The receiving half of :class:`pectoral_gym.hardware.radio.link.RadioLink`: the robot's STATUS messages, counters.

:class:`StatusReceiver` is the half of ``RadioLink`` that reads the port in a thread of its own, decodes the
robot's STATUS messages, acknowledges commands, measures the round trip (Karn's rule) and the robot's clock,
and latches a loss of control (``taken_over``, ``robot_busy``, ``robot_rebooted``). It holds no state of its
own: it works on the link's attributes (named in its docstring) under the link's lock.
"""

from __future__ import annotations

from dataclasses import dataclass

import serial

from pectoral_gym.hardware.radio import protocol as pr

__all__ = ["LinkStats", "StatusReceiver"]


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
        foreign: STATUS messages addressed to other sessions (heard, not taken as acks).
        suppressed: Commands not sent because control is lost.
        latches: The robot's latch reports (LATCH) received, addressed to us, new.
        latches_lost: Latch reports missing from their own numbering (lost on the radio).
        latches_unplaced: Latch reports dropped because the robot's clock (that boot's) was not known yet.
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
    foreign: int = 0
    suppressed: int = 0
    latches: int = 0
    latches_lost: int = 0
    latches_unplaced: int = 0


class StatusReceiver:
    """Mix-in of :class:`pectoral_gym.hardware.radio.link.RadioLink`: reading and STATUS handling.

    Uses the link's ``serial``, ``clock`` (a :class:`pectoral_gym.hardware.clock.Clock`), ``decoder``,
    ``tracker``, ``stats``, ``session``, ``boot``, ``served``, ``robot_clock``, ``rtt_estimator``,
    ``last_status``/``last_status_time``, ``command``, ``lease_end``, ``control_lost``, ``take_over`` and its
    private bookkeeping (``_lock``, ``_acked_event``, ``_stop``, ``_pending``, ``_sent_at``, ``_acked``, ``_quiet``,
    ``_served``, ``_commanded``, ``_old_boots``, ``ack_log``); for the latch reports ``latch_tracker``,
    ``latch_reports`` and ``lease_scale``.
    """

    def _read_loop(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.serial.read(max(1, self.serial.in_waiting))
            except (serial.SerialException, OSError, TypeError, AttributeError):
                if self._stop.is_set():
                    return
                self.clock.sleep(0.01)
                continue
            if data:
                self._receive(data)

    def _lose(self, reason: str) -> None:
        """Latch ``reason`` in :attr:`control_lost` (the first one stays); our command is void."""
        if not self.control_lost:
            self.control_lost = reason
        self.command = None
        self.lease_end = -float("inf")
        if reason != "robot_rebooted":  # another session is served: no retry of ours may reach its fins
            self._pending = None

    def _receive(self, data: bytes) -> None:
        messages = self.decoder.feed(data)
        with self._lock:
            d = self.decoder
            self.stats.crc_errors, self.stats.checksum_errors = d.crc_errors, d.checksum_errors
            self.stats.framing_errors = d.framing_errors + d.truncated
            for msg in messages:
                if msg.type == pr.MsgType.LATCH:
                    self._latch(msg)
                    continue
                if msg.type != pr.MsgType.STATUS:
                    continue  # our own frames echoed (loop://) or a confused peer
                status = msg.status
                if status.boot in self._old_boots:
                    self.stats.stale += 1  # a late answer from before a reboot
                    continue
                verdict = self.tracker.check(msg.seq, status.boot)  # a rebooted robot numbers afresh
                self.stats.duplicates, self.stats.stale = self.tracker.duplicates, self.tracker.stale
                self.stats.dropped = self.tracker.lost
                if verdict != pr.Verdict.NEW:
                    continue
                self._status(msg)
            self._acked_event.notify_all()

    def _latch(self, msg: pr.Message) -> None:
        """A LATCH report (call with the lock held): kept, on the PC's clock, if it is about our fins.

        Reports are fire and forget: a lost one shows as a gap in their own numbering (``latches_lost``) and
        costs the replay only that half-stroke's pattern (it infers it, as without reports).
        """
        latch = msg.latch
        if msg.session != self.session or latch.boot in self._old_boots:
            return  # another PC's fins, or a report from before a reboot
        verdict = self.latch_tracker.check(msg.seq, latch.boot)
        self.stats.latches_lost = self.latch_tracker.lost
        if verdict != pr.Verdict.NEW:
            return
        t = self.robot_clock.pc_time(latch.boot, latch.uptime_ms, 1.0 / self.lease_scale)
        if t is None:
            self.stats.latches_unplaced += 1  # no STATUS of that boot yet: its clock is unknown
            return
        self.stats.latches += 1
        self.latch_reports.append((t, latch))

    def drain_latches(self) -> list[tuple[float, pr.Latch]]:
        """The latch reports received since the last call: ``(PC clock time of the latch [s], report)``, in order."""
        with self._lock:
            out = list(self.latch_reports)
            self.latch_reports.clear()
        return out

    def _status(self, msg: pr.Message) -> None:
        """A new STATUS, addressed to us or not (call with the lock held)."""
        status, now = msg.status, self.clock.monotonic()
        if self.boot is not None and status.boot != self.boot:  # a brown-out: its fins stopped, its rules reset
            if self._served or self._commanded:
                self._lose("robot_rebooted")
            self._old_boots.append(self.boot)
            self._served, self._commanded, self._pending = False, False, None
        self.boot, self.served = status.boot, status.served
        sent = self._sent_at.get(status.ack_seq) if msg.session == self.session else None
        once = sent is not None and not sent[1]  # Karn: of a message sent more than once, which copy is unknown
        self.robot_clock.add(status.boot, status.uptime_ms, now, sent[0] if once else None)  # any STATUS tells
        if msg.session != self.session:
            self.stats.foreign += 1  # another PC's answer: no ack, no liveness, but whom the robot serves
            if self._served and status.served != self.session:
                self._lose("taken_over")
                self._served = False
            return
        self.stats.received += 1
        self.last_status, self.last_status_time = status, now
        if once:
            self.rtt_estimator.update(now - sent[0])
            self._sent_at.pop(status.ack_seq)
        if status.served == self.session:
            self._served = True
        else:  # refused: another session is served (with take_over we keep claiming until we are)
            if not (self.take_over and not self._served):
                self._lose("taken_over" if self._served else "robot_busy")
            self._served = False
        ack = status.ack_seq
        if self._pending is not None and self._satisfies(status, self._pending):
            self._pending = None
            self.stats.acked += 1
        if status.state != pr.RobotState.RUNNING:
            if self._quiet is None or pr.serial_newer(ack, self._quiet) or ack == self._quiet:
                self._quiet = ack
            if self.command is None:
                self._commanded = False
        self.ack_log.append((now, ack))
        self._acked.add(ack)
        if len(self._acked) > 1024:
            self._acked = {ack}

    def acknowledged_at(self, seq: int) -> float | None:
        """``clock.monotonic()`` of the first STATUS to us answering message ``seq`` or a later one, or ``None``.

        By then the robot had received ``seq`` or something newer (a keep-alive copy of the same command, or a
        command that replaced it): the latest instant the robot can have taken the command ``seq`` carries.
        ``None`` while no such STATUS has arrived (or it is older than the last 512).
        """
        with self._lock:
            for t, ack in self.ack_log:
                if ack == seq or pr.serial_newer(ack, seq):
                    return t
        return None

    @staticmethod
    def _satisfies(status: pr.Status, pending: tuple) -> bool:
        """Whether ``status`` (addressed to us) settles the pending command.

        Its own ack does, and so does the ack of a later keep-alive that repeats it (the keep-alive always
        carries the current command; after a STOP the robot must also report that it is not running).
        """
        seq, mtype = pending[0], pending[4]
        if status.ack_seq == seq:
            return True
        return pr.serial_newer(status.ack_seq, seq) and (mtype == pr.MsgType.SET_FINS
                                                         or status.state != pr.RobotState.RUNNING)
