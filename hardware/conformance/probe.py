"""The conformance suite's radio: raw protocol messages to a robot and its answers, timed on one clock.

Unlike :class:`pectoral_gym.hardware.radio.link.RadioLink`, which keeps a robot safe, :class:`Probe` sends exactly
what a scenario asks for: several sessions, duplicates (the same sequence number again), stale numbers, copies
of a command, deadlines in the past or for another boot, a frame whose CRC-16 is wrong under a good XBee
checksum. It sends Transmit Requests (``0x10``) as the PC's XBee takes them and reads the Receive Packets
(``0x90``) the robot's answers arrive in (``docs/protocol.md`` sections 1-3).

Every answer is kept with the PC time it arrived; STATUS and LATCH carry the robot's own clock (``uptime_ms``),
and the scenarios judge timing on that clock, so the radio's latency does not enter the verdicts (only how long
the probe waits for an answer, :attr:`Probe.reply_timeout`, from the round trip measured at the start).
"""

from __future__ import annotations

import secrets
import statistics
from dataclasses import dataclass, replace

import numpy as np

from pectoral_gym.hardware.clock import REAL_CLOCK, Clock
from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio import xbee as xb

__all__ = ["READ_SLICE", "Answer", "Probe", "Session", "with_seq"]

READ_SLICE = 0.01  # the serial port's read timeout [PC s]: waits are cut into reads this long


@dataclass(frozen=True)
class Answer:
    """A message from the robot and the PC time it arrived [PC s on the probe's clock]."""

    t: float
    msg: pr.Message

    @property
    def status(self) -> pr.Status:
        """The STATUS body (for STATUS answers)."""
        assert self.msg.status is not None
        return self.msg.status


class Session:
    """One PC session as the probe plays it: its id, its sequence numbers and command identities.

    Args:
        probe: The probe that sends for it.
        session: The 32-bit session id (nonzero).
    """

    def __init__(self, probe: Probe, session: int):
        self.probe, self.id = probe, int(session) & 0xFFFFFFFF
        self.seq = 0
        self.command = 0
        self.last: pr.Message | None = None

    def message(self, kind: pr.MsgType, **fields) -> pr.Message:
        """The session's next message of type ``kind`` (the sequence number advances)."""
        self.seq = (self.seq + 1) & 0xFFFF
        return pr.Message(kind, self.seq, self.id, **fields)

    def set_fins(self, beats: np.ndarray, lease: float = 1.0, deadline: int = 0, boot: int = 0,
                 command: int | None = None) -> pr.Message:
        """A SET_FINS of ``beats`` ``(2, 4)`` [rad, rad, s, -]; a new command identity unless ``command`` is given."""
        if command is None:
            self.command = (self.command + 1) & 0xFFFF
            command = self.command
        fins = tuple(float(v) for v in np.asarray(beats, dtype=float).reshape(8))
        return self.message(pr.MsgType.SET_FINS, fins=fins, command=command, lease=lease, deadline=deadline,
                            boot=boot)

    def send(self, msg: pr.Message, expect: bool = True) -> Answer | None:
        """Send ``msg`` and wait for the STATUS that answers it (``expect=False``: send only, return ``None``)."""
        self.last = msg
        return self.probe.exchange(msg, expect)

    def post(self, msg: pr.Message) -> pr.Message:
        """Send ``msg`` without waiting (its answer is found later by :meth:`Probe.answer_to`); returns it.

        Where a rule's timing matters, a scenario must not wait a round trip between messages: over a slow
        radio the robot would see the session fall silent (the watchdog) or a lease run out in between.
        """
        self.last = msg
        self.probe.exchange(msg, expect=False)
        return msg

    def heartbeat(self) -> Answer | None:
        """A new HEARTBEAT, answered."""
        return self.send(self.message(pr.MsgType.HEARTBEAT))

    def repeat(self) -> Answer | None:
        """The last message again, unchanged (a duplicate: same sequence number), answered."""
        assert self.last is not None
        return self.probe.exchange(self.last, True)


class Probe:
    """Sends protocol messages over a byte stream and collects the robot's answers.

    Args:
        port: A serial-like object: ``write(bytes)`` and ``read(size)`` (a pyserial port opened with a short
            timeout, 0.01 s, or a :class:`pectoral_gym.hardware.radio.pipe.StreamEnd`, read with a timeout).
        clock: The PC's clock (a ``VirtualClock`` with an in-process emulator in lockstep).
        speed: Robot seconds per PC second (an accelerated emulator); robot durations are divided by it.
        dest64: The robot XBee's 64-bit address (broadcast by default).
        rng: Where session ids come from (``None``: the OS's secure source, as a real PC must).

    Attributes:
        answers: Every valid message received, in arrival order.
        reply_timeout: How long to wait for a STATUS [robot s]; :meth:`measure_rtt` sets it from the round trip.
        resent: Messages sent again because their answer did not come (a lossy radio).
    """

    def __init__(self, port, clock: Clock = REAL_CLOCK, speed: float = 1.0, dest64: int = xb.BROADCAST,
                 rng: np.random.Generator | None = None):
        self.port, self.clock, self.speed, self.dest64 = port, clock, float(speed), int(dest64)
        self.decoder = pr.StreamDecoder()
        self.answers: list[Answer] = []
        self.reply_timeout = 0.3
        self.retries = 2
        self.resent = 0
        self.rtts: list[float] = []
        self.rtt_max = 0.0  # slowest round trip measured by measure_rtt [robot s]
        self.outgoing: list[pr.Message] = []  # every message sent through exchange (posts included), in order
        self.unanswerable = 0  # messages sent that must go unanswered (stale, bad CRC)
        self.cache: dict = {}  # runs that several scenarios judge (fins.py's latch run); cleared for a re-run
        self.reboot_robot = None  # a callable that power-cycles the robot, where the transport allows it
        self._rng = rng
        self._stream = hasattr(port, "peer")  # a StreamEnd: reads wait on the clock

    # ------------------------------------------------------------ sessions and time
    def session(self) -> Session:
        """A fresh session with a random nonzero id."""
        sid = int(self._rng.integers(1, 2**32)) if self._rng is not None else (secrets.randbits(32) or 1)
        return Session(self, sid)

    def now(self) -> float:
        """The PC's clock [PC s]."""
        return self.clock.monotonic()

    def wait(self, seconds: float) -> None:
        """Let ``seconds`` of robot time pass, collecting what arrives."""
        end = self.now() + seconds / self.speed
        while self.now() < end:
            self._read(end - self.now())

    # ------------------------------------------------------------ bytes
    def write_raw(self, frame: bytes) -> None:
        """Write one escaped XBee frame (or any bytes) as they are."""
        self.port.write(frame)

    def frame(self, msg: pr.Message, corrupt_crc: bool = False) -> bytes:
        """The Transmit Request frame carrying ``msg`` (``corrupt_crc``: its CRC-16 wrong, the XBee checksum right)."""
        payload = bytearray(pr.encode_message(msg))
        if corrupt_crc:
            payload[-1] ^= 0x01
        return xb.encode_frame(xb.tx_request(bytes(payload), self.dest64))

    def _read(self, timeout: float) -> None:
        if self._stream:
            data = self.port.read(4096, timeout=max(timeout, 0.0))
        else:  # a serial port opened with a timeout of about READ_SLICE (reconfiguring it per read costs a syscall)
            data = self.port.read(max(1, getattr(self.port, "in_waiting", 0) or 1))
        if data:
            t = self.now()
            self.answers.extend(Answer(t, m) for m in self.decoder.feed(data))

    def exchange(self, msg: pr.Message, expect: bool = True) -> Answer | None:
        """Send ``msg``; with ``expect``, wait for the new STATUS answering it (re-sent unchanged if none comes).

        A STATUS answers ``msg`` when it is addressed to its session and acknowledges its sequence number and
        type. Returns ``None`` when none came after :attr:`retries` re-sendings.
        """
        self.outgoing.append(msg)
        for attempt in range(self.retries + 1 if expect else 1):
            if attempt:
                self.resent += 1
            sent, start = self.now(), len(self.answers)
            self.write_raw(self.frame(msg))
            if not expect:
                return None
            answer = self.await_status(msg, start, self.reply_timeout)
            if answer is not None:
                if not attempt:
                    self.rtts.append(answer.t - sent)
                return answer
        return None

    def await_status(self, msg: pr.Message, start: int, timeout: float) -> Answer | None:
        """The first STATUS from ``answers[start:]`` on that answers ``msg``, waiting up to ``timeout`` robot s."""
        end = self.now() + timeout / self.speed
        while True:
            for answer in self.answers[start:]:
                s = answer.msg.status
                if (answer.msg.type == pr.MsgType.STATUS and answer.msg.session == msg.session and s is not None
                        and s.ack_seq == msg.seq and s.ack_type == int(msg.type)):
                    return answer
            start = len(self.answers)
            if self.now() >= end:
                return None
            self._read(end - self.now())

    def mark(self) -> tuple[int, int, int]:
        """A point to ask :meth:`lost_since` about: ``(messages sent, re-sendings, unanswerable)`` so far."""
        return len(self.outgoing), self.resent, self.unanswerable

    def lost_since(self, mark: tuple[int, int, int]) -> int:
        """Messages since ``mark`` that a lossy radio may have lost, after a wait for the answers on their way.

        Those unanswered or re-sent; and, once the radio has lost any message, those that must go unanswered
        (their loss looks like the robot ignoring them). A scenario that failed over such a radio may have failed
        on the loss, not on the robot: it is run again.
        """
        self.wait(self.reply_timeout)
        heard = {(a.msg.session, a.status.ack_seq, a.status.ack_type) for a in self.statuses()}
        unanswered = sum((m.session, m.seq, int(m.type)) not in heard for m in self.outgoing[mark[0]:])
        lost = unanswered + self.resent - mark[1]
        lossy = lost or self.resent or any((m.session, m.seq, int(m.type)) not in heard for m in self.outgoing)
        return lost + (self.unanswerable - mark[2] if lossy else 0)

    def answer_to(self, msg: pr.Message) -> Answer | None:
        """The STATUS answering ``msg`` among everything received, waiting up to :attr:`reply_timeout` for it."""
        return self.await_status(msg, 0, self.reply_timeout)

    def silent_after(self, msg: pr.Message, corrupt_crc: bool = False) -> bool:
        """Send ``msg`` that must go unanswered, and wait :attr:`reply_timeout`: whether nothing answered it.

        Counted in :attr:`unanswerable`: over a radio that has lost messages, its own loss cannot be told
        from a robot that ignored it (:meth:`lost_since`).
        """
        start = len(self.answers)
        self.unanswerable += 1
        self.write_raw(self.frame(msg, corrupt_crc))
        return self.await_status(msg, start, self.reply_timeout) is None

    # ------------------------------------------------------------ what was heard
    def latches(self, since_ms: int, boot: int) -> list[pr.Message]:
        """LATCH reports of boot ``boot`` from robot uptime ``since_ms`` on, in arrival order.

        Chosen by the robot's clock, not by when they arrived: reports from before a scenario's start may still
        be on their way when it starts.
        """
        return [a.msg for a in self.answers if a.msg.type == pr.MsgType.LATCH and a.msg.latch.boot == boot
                and a.msg.latch.uptime_ms >= since_ms]

    def statuses(self) -> list[Answer]:
        """Every STATUS received, in arrival order."""
        return [a for a in self.answers if a.msg.type == pr.MsgType.STATUS]

    def robot_uptime_ms(self) -> float:
        """The robot's clock now, estimated from the newest STATUS [ms]: its uptime plus the PC time since."""
        newest = self.statuses()[-1]
        return newest.status.uptime_ms + 1000.0 * (self.now() - newest.t) * self.speed

    def measure_rtt(self, count: int = 10) -> dict[str, float]:
        """Send ``count`` HEARTBEATs one at a time; set :attr:`reply_timeout` from the round trips [robot s].

        The timeout is 3 times the slowest round trip plus 0.1 s, at least 0.25 s: a reply later than that
        counts as lost (then the message is re-sent, as the PC's link does).
        """
        self.reply_timeout = 1.0  # generous while nothing is known
        session = self.session()
        rtts = []
        for _ in range(count):
            msg = session.message(pr.MsgType.HEARTBEAT)
            sent, resent = self.now(), self.resent
            answer = self.exchange(msg)
            if answer is not None and self.resent == resent:  # Karn: not from a re-sent message's answer
                rtts.append((answer.t - sent) * self.speed)
        if not rtts:
            raise ConnectionError(f"no STATUS answered {count} HEARTBEATs at their first sending: is the robot on, "
                                  "and the port right?")
        self.reply_timeout = max(0.25, 3.0 * max(rtts) + 0.1)
        self.rtt_max = max(rtts)
        return {"median": statistics.median(rtts), "max": max(rtts), "answered": len(rtts), "sent": count,
                "reply_timeout": self.reply_timeout, "session": session.id}


def with_seq(msg: pr.Message, seq: int) -> pr.Message:
    """``msg`` with sequence number ``seq`` (a stale or replayed copy)."""
    return replace(msg, seq=seq & 0xFFFF)
