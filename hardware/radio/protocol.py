"""Wire protocol between the PC and the robotic fish: the messages carried inside XBee API frames.

Two layers (byte layouts, timing and rules in ``docs/protocol.md``); the outer one, the escaped XBee API frame
(AP = 2), is :mod:`pectoral_gym.hardware.radio.xbee`'s. This module is the inner one:

* **Message** (the RF data inside those frames): ``version, type, session (u32), seq (u16)``, a body, and a
  CRC-16/CCITT-FALSE of everything before it (the XBee checksum is only 8 bits). Big endian throughout.
  Version 3: a SET_FINS carries a command identity, a lease and a deadline on the robot's clock (with the
  robot's boot id it refers to): the robot runs a command until the lease, counted from its own receipt
  of the command's first copy, or the deadline, whichever comes first; copies never extend it. A STATUS
  is addressed to the session of the message it answers and tells whom the robot serves and its boot id.

Encoders and decoders are pure functions; :class:`StreamDecoder` turns an arbitrary byte stream into
valid messages (it resynchronises on garbage and never yields a damaged message) and
:class:`SequenceTracker` classifies sequence numbers as new, duplicate or stale (16-bit wrap-around).
"""

from __future__ import annotations

import binascii
import enum
import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field

from pectoral_gym.hardware.radio.xbee import ESCAPE, MAX_FRAME_DATA, START, ProtocolError, checksum, rf_data
from pectoral_gym.model.finrules import FIN_WIRE_SCALE, fin_words

__all__ = [
    "PROTOCOL_VERSION", "MAX_LEASE", "DEFAULT_LEASE", "state_name",
    "MsgType", "RobotState", "Status", "Latch", "Message",
    "crc16", "encode_message", "decode_message",
    "StreamDecoder", "SequenceTracker", "Verdict", "serial_newer",
]

PROTOCOL_VERSION = 3  # 3: STATUS with served session and boot id, SET_FINS with a deadline; CLAIM
MAX_LEASE = 1.0  # longest lease a SET_FINS may carry [s]
DEFAULT_LEASE = 0.8  # lease of a command from step(): 0.5 s control period + 0.3 s jitter (docs/protocol.md)

_HEADER = struct.Struct(">BBIH")  # version, type, session, seq
_FINS = struct.Struct(">8H")  # per fin: bias [mrad], amplitude [mrad], period [ms], ratio [1/1000]
_LEASE = struct.Struct(">HHII")  # command identity, lease [ms], deadline [robot uptime ms, 0 = none], boot id
# ack seq, ack type, state, flags, crc errors, duplicates, stale, uptime [ms], served session, boot id
_STATUS = struct.Struct(">HBBBHHHIII")
# uptime [ms], boot id, fin (0 right, 1 left), flags (bit 0: a power stroke starts), turning-point angle [mrad],
# the pattern latched: bias [mrad], amplitude [mrad], period [ms], ratio [1/1000]
_LATCH = struct.Struct(">IIBBH4H")
_CRC = struct.Struct(">H")
_FIN_SCALE = FIN_WIRE_SCALE  # SI value * scale = wire integer (the robot's resolution of a pattern: the core's)


class MsgType(enum.IntEnum):
    """Message types (byte 1 of a message)."""

    SET_FINS = 0x01  # PC -> robot: both fins' (bias, amplitude, period, ratio), absolute setpoints
    STOP = 0x02  # PC -> robot: hold both fins still now
    HEARTBEAT = 0x03  # PC -> robot: keep-alive, changes nothing
    CLAIM = 0x04  # PC -> robot: take the robot over from another live session (an explicit operator action)
    STATUS = 0x81  # robot -> PC: acknowledgement and health
    LATCH = 0x82  # robot -> PC: a fin latched a pattern at a stroke turning point (report, never acknowledged)


class RobotState(enum.IntEnum):
    """The robot's state, reported in :class:`Status`."""

    IDLE = 0  # powered up, no command yet; fins still
    RUNNING = 1  # beating its fins at the commanded pattern
    STOPPED = 2  # stopped by a STOP message; fins still
    WATCHDOG = 3  # no valid frame for the watchdog time; fins still
    EXPIRED = 4  # the running command's lease ran out; fins still


def state_name(state: int) -> str:
    """Name of a reported robot state; ``"UNKNOWN_<n>"`` for a value this PC does not know."""
    try:
        return RobotState(state).name
    except ValueError:
        return f"UNKNOWN_{int(state)}"


class StatusFlag(enum.IntFlag):
    """Bits of :attr:`Status.flags`."""

    CLIPPED = 0x01  # the last SET_FINS was clipped to the servo limits
    RATE_LIMITED = 0x02  # a fin's last latch ran less than the last SET_FINS (the rate rule held it back)


@dataclass(frozen=True)
class Status:
    """Body of a STATUS message: which message it acknowledges, whom the robot serves, its health counters.

    ``served`` is the session the robot obeys (0: none yet); ``boot`` the robot's boot id (random, nonzero,
    new at every power-up); ``uptime_ms`` its clock since that power-up, read when the STATUS is built.
    """

    ack_seq: int
    ack_type: int
    state: int
    flags: int = 0
    crc_errors: int = 0
    duplicates: int = 0
    stale: int = 0
    uptime_ms: int = 0
    served: int = 0
    boot: int = 0


@dataclass(frozen=True)
class Latch:
    """Body of a LATCH message: fin ``fin`` started a half-stroke of pattern ``beat`` at robot uptime ``uptime_ms``.

    ``beat`` is ``(bias, amplitude, period, ratio)`` [rad, rad, s, -] as the fin runs it (the rate-limited
    setpoint with the transitional stretch, ``finrules.stretch_transition``), quantised like SET_FINS;
    ``turn`` [rad] the fin angle at the turning point (where the half-stroke starts); ``power`` whether it
    is a power stroke (to ``bias + amplitude``) or a recovery (to ``bias - amplitude``). With these the
    half-stroke is known whole: the PC needs no earlier report to replay it (a lost report costs nothing
    after the next one). ``boot`` names the clock ``uptime_ms`` is on.
    """

    uptime_ms: int
    boot: int
    fin: int
    power: bool
    turn: float
    beat: tuple[float, float, float, float]


@dataclass(frozen=True)
class Message:
    """One message: its type, sequence number, session and the body fields of its type.

    ``session`` is the sender's (a PC) or, in a STATUS, the session of the message it answers. SET_FINS:
    ``fins`` (8 floats, right fin first, SI), ``command``, ``lease``, ``deadline``, ``boot``; STATUS: ``status``;
    LATCH: ``latch`` (its ``session`` is the one the robot serves, its ``seq`` the robot's count of LATCH messages).

    ``command`` (u16) names the command: copies (keep-alives, retries) carry the same one, a new command
    from the controller a newer one. ``lease`` [s, ms resolution, (0, MAX_LEASE]] is how long the robot
    may run it after receiving its first copy. ``deadline`` (u32) is the robot uptime [ms] at which it must
    stop whatever the lease says, valid for the robot boot ``boot`` (u32); ``deadline = 0``: no deadline
    (the PC has not synchronised to the robot's clock yet).
    """

    type: MsgType
    seq: int
    session: int = 0
    fins: tuple[float, ...] | None = None
    status: Status | None = field(default=None)
    latch: Latch | None = None
    command: int = 0
    lease: float = DEFAULT_LEASE
    deadline: int = 0
    boot: int = 0


# ---------------------------------------------------------------- checks
def serial_newer(a: int, b: int, bits: int = 16) -> bool:
    """Whether ``a`` is after ``b`` in serial-number arithmetic: ``1 <= (a - b) mod 2**bits < 2**(bits - 1)``."""
    d = (int(a) - int(b)) % (1 << bits)
    return 0 < d < (1 << (bits - 1))


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final xor (check 0x29B1).

    ``data``: any bytes-like object. ``binascii.crc_hqx`` is this CRC (CCITT's polynomial, unreflected, no final
    xor) from the initial value it is given, in C: a message's CRC costs a few hundred times less than a bitwise
    loop in Python.
    """
    return binascii.crc_hqx(data, 0xFFFF)


# ---------------------------------------------------------------- messages
def _fins_to_wire(fins: Sequence[float]) -> bytes:
    return _FINS.pack(*fin_words(fins))


def _latch_to_wire(latch: Latch | None) -> bytes:
    if latch is None:
        raise ValueError("LATCH needs latch")
    if latch.fin not in (0, 1):
        raise ValueError(f"LATCH fin must be 0 (right) or 1 (left), got {latch.fin!r}")
    turn = round(float(latch.turn) * 1000.0) if math.isfinite(latch.turn) else -1
    if not 0 <= turn <= 0xFFFF:
        raise ValueError(f"LATCH turn = {latch.turn!r} rad does not fit the wire format (0..65.535 rad)")
    pattern = _FINS.unpack(_fins_to_wire((*latch.beat, *latch.beat)))[:4]
    return _LATCH.pack(int(latch.uptime_ms) & 0xFFFFFFFF, int(latch.boot) & 0xFFFFFFFF, latch.fin,
                       1 if latch.power else 0, turn, *pattern)


def encode_message(msg: Message) -> bytes:
    """RF data of ``msg``: header, body, CRC-16."""
    if not 0 <= msg.seq <= 0xFFFF or not 0 <= msg.session <= 0xFFFFFFFF:
        raise ValueError(f"seq must be 0..65535 and session 0..2**32-1, got {msg.seq}, {msg.session}")
    if msg.type == MsgType.SET_FINS:
        if msg.fins is None:
            raise ValueError("SET_FINS needs fins")
        lease_ms = round(float(msg.lease) * 1000.0) if math.isfinite(msg.lease) else -1
        if not 1 <= lease_ms <= round(MAX_LEASE * 1000) or not 0 <= msg.command <= 0xFFFF:
            raise ValueError(f"SET_FINS needs a lease in (0, {MAX_LEASE}] s and a command 0..65535, "
                             f"got {msg.lease!r}, {msg.command!r}")
        if not 0 <= msg.deadline <= 0xFFFFFFFF or not 0 <= msg.boot <= 0xFFFFFFFF:
            raise ValueError(f"SET_FINS needs a deadline and a boot id 0..2**32-1, got {msg.deadline!r}, "
                             f"{msg.boot!r}")
        body = _fins_to_wire(msg.fins) + _LEASE.pack(msg.command, lease_ms, msg.deadline, msg.boot)
    elif msg.type == MsgType.STATUS:
        if msg.status is None:
            raise ValueError("STATUS needs status")
        s = msg.status
        body = _STATUS.pack(s.ack_seq & 0xFFFF, s.ack_type & 0xFF, s.state & 0xFF, s.flags & 0xFF,
                            min(s.crc_errors, 0xFFFF), min(s.duplicates, 0xFFFF), min(s.stale, 0xFFFF),
                            s.uptime_ms & 0xFFFFFFFF, s.served & 0xFFFFFFFF, s.boot & 0xFFFFFFFF)
    elif msg.type == MsgType.LATCH:
        body = _latch_to_wire(msg.latch)
    else:
        body = b""
    head = _HEADER.pack(PROTOCOL_VERSION, int(msg.type), msg.session, msg.seq) + body
    return head + _CRC.pack(crc16(head))


_BODY_SIZE = {MsgType.SET_FINS: _FINS.size + _LEASE.size, MsgType.STOP: 0, MsgType.HEARTBEAT: 0,
              MsgType.CLAIM: 0, MsgType.STATUS: _STATUS.size, MsgType.LATCH: _LATCH.size}


def decode_message(payload: bytes) -> Message:
    """Parse RF data into a :class:`Message`.

    Raises:
        ProtocolError: Not a valid message (``reason``: ``crc``, ``length``, ``version``, ``type`` or ``field``).
    """
    if len(payload) < _HEADER.size + _CRC.size:
        raise ProtocolError("length", f"message of {len(payload)} bytes is shorter than header + CRC")
    (crc,) = _CRC.unpack_from(payload, len(payload) - 2)
    if crc16(payload[:-2]) != crc:
        raise ProtocolError("crc", f"CRC-16 mismatch (got 0x{crc:04X})")
    version, kind, session, seq = _HEADER.unpack_from(payload)
    if version != PROTOCOL_VERSION:
        raise ProtocolError("version", f"protocol version {version}, expected {PROTOCOL_VERSION}")
    try:
        mtype = MsgType(kind)
    except ValueError:
        raise ProtocolError("type", f"unknown message type 0x{kind:02X}") from None
    body = payload[_HEADER.size:-2]
    if len(body) != _BODY_SIZE[mtype]:
        raise ProtocolError("length", f"{mtype.name} body of {len(body)} bytes, expected {_BODY_SIZE[mtype]}")
    if mtype == MsgType.SET_FINS:
        words = _FINS.unpack_from(body)
        fins = tuple(w / _FIN_SCALE[i % 4] for i, w in enumerate(words))
        command, lease_ms, deadline, boot = _LEASE.unpack_from(body, _FINS.size)
        return Message(mtype, seq, session, fins=fins, command=command, lease=lease_ms / 1000.0, deadline=deadline,
                       boot=boot)
    if mtype == MsgType.STATUS:
        return Message(mtype, seq, session, status=Status(*_STATUS.unpack(body)))
    if mtype == MsgType.LATCH:
        uptime, boot, fin, flags, turn, *pattern = _LATCH.unpack(body)
        if fin > 1:
            raise ProtocolError("field", f"LATCH of fin {fin}; fins are 0 (right) and 1 (left)")
        beat = tuple(w / _FIN_SCALE[i] for i, w in enumerate(pattern))
        return Message(mtype, seq, session, latch=Latch(uptime, boot, fin, bool(flags & 1), turn / 1000.0, beat))
    return Message(mtype, seq, session)


# ---------------------------------------------------------------- streaming
class StreamDecoder:
    """Resynchronising decoder: bytes in, valid messages out.

    Any byte sequence is accepted. Bytes before a start delimiter are skipped; a ``0x7E`` inside a
    frame abandons that frame and starts a new one; a length above ``MAX_FRAME_DATA``, a bad
    escape, a bad checksum or a bad CRC drops the frame. Only messages that pass every check are
    returned. Counters (cumulative): ``frames`` (good XBee frames), ``messages``, ``skipped_bytes``,
    ``framing_errors``, ``truncated``, ``checksum_errors``, ``crc_errors``, ``malformed`` (other
    message errors), ``other_frames`` (valid frames of other XBee types, e.g. Transmit Status).
    """

    def __init__(self):
        self._buf = bytearray()
        self._in_frame = False
        self._escaped = False
        self._need = 2  # the frame's bytes (after the delimiter) at which _check has something to decide
        self.frames = self.messages = self.skipped_bytes = self.framing_errors = 0
        self.truncated = self.checksum_errors = self.crc_errors = self.malformed = self.other_frames = 0

    def counters(self) -> dict[str, int]:
        """All error and traffic counters."""
        names = ("frames", "messages", "skipped_bytes", "framing_errors", "truncated", "checksum_errors",
                 "crc_errors", "malformed", "other_frames")
        return {name: getattr(self, name) for name in names}

    def feed(self, data: bytes) -> list[Message]:
        """Consume ``data``; return the messages completed by it (possibly none)."""
        out: list[Message] = []
        for byte in data:
            if byte == START:
                if self._in_frame and self._buf:
                    self.truncated += 1  # a new frame began before the previous one was complete
                self._buf.clear()
                self._in_frame, self._escaped, self._need = True, False, 2
                continue
            if not self._in_frame:
                self.skipped_bytes += 1
                continue
            if self._escaped:
                byte ^= 0x20
                self._escaped = False
            elif byte == ESCAPE:
                self._escaped = True
                continue
            self._buf.append(byte)
            if len(self._buf) >= self._need:  # the length field complete, or the whole frame
                self._check(out)
        return out

    def _check(self, out: list[Message]) -> None:
        buf = self._buf
        if len(buf) < 2:
            return
        length = (buf[0] << 8) | buf[1]
        if length == 0 or length > MAX_FRAME_DATA:
            self.framing_errors += 1
            self._in_frame = False
            return
        if len(buf) < length + 3:
            self._need = length + 3
            return
        data, cs = bytes(buf[2:-1]), buf[-1]
        self._in_frame = False
        if checksum(data) != cs:
            self.checksum_errors += 1
            return
        self.frames += 1
        payload = rf_data(data)
        if payload is None:
            self.other_frames += 1
            return
        try:
            msg = decode_message(payload)
        except ProtocolError as err:
            if err.reason == "crc":
                self.crc_errors += 1
            else:
                self.malformed += 1
            return
        self.messages += 1
        out.append(msg)


class Verdict(enum.Enum):
    """Classification of a received sequence number."""

    NEW = "new"
    DUPLICATE = "duplicate"
    STALE = "stale"


class SequenceTracker:
    """Sequence-number bookkeeping of one direction (serial-number arithmetic, 16-bit wrap-around).

    ``d = (seq - last) mod 2**16``: ``d = 0`` duplicate; ``1 <= d < 2**15`` new (``d - 1`` messages
    lost in between); ``d >= 2**15`` stale (older than the last one: reordered or a late retry). A
    change of ``session`` or :meth:`reset` accepts the next number as new. The robot keys its tracker
    by the PC's session; the PC keys its tracker by the robot's boot id (a rebooted robot numbers afresh).
    """

    def __init__(self):
        self.last: int | None = None
        self.session: int | None = None
        self.new = self.duplicates = self.stale = self.lost = 0

    def reset(self) -> None:
        """Forget the last number (after a watchdog timeout or a reconnect)."""
        self.last = None

    def check(self, seq: int, session: int = 0) -> Verdict:
        """Classify ``seq`` and update the counters; a new number becomes the last one."""
        if self.last is None or session != self.session:
            self.last, self.session = seq, session
            self.new += 1
            return Verdict.NEW
        d = (seq - self.last) & 0xFFFF
        if d == 0:
            self.duplicates += 1
            return Verdict.DUPLICATE
        if d >= 0x8000:
            self.stale += 1
            return Verdict.STALE
        self.lost += d - 1
        self.last = seq
        self.new += 1
        return Verdict.NEW
