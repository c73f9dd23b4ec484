"""Generated message streams for the differential test of the firmware: the events a robot's clock and radio see.

Helper of ``tests/test_firmware_differential.py`` (the float32 bound and the comparison rules are argued there).
A :class:`Stream` is a list of events on the robot's millisecond clock (ticks, received bytes, reboots) from the
traffic of one or more PCs (:func:`generate`); the robots they drive and what those report:
``tests/firmware_robots.py``.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio import xbee as xb


@dataclass
class Stream:
    """Events ``(t_ms, kind, data)``: ``tick``, ``rx`` (bytes), ``reboot`` (new boot id); clock = ``clock0 + t``."""

    seed: int
    boot: int
    uptime0: int  # uptime [ms] at t = 0 (near 2**32: the uptime wraps within the stream)
    clock0: int  # the C clock at t = 0 (near 2**32: the clock wraps)
    reboot: tuple[int, int] | None = None  # (t, new boot id) of a power-up within the stream
    events: list[tuple[int, str, object]] = field(default_factory=list)


# ---------------------------------------------------------------- streams
def message(kind: int, session: int, seq: int, body: bytes = b"") -> bytes:
    """RF data of a message, built by hand (so leases the encoder refuses can be sent)."""
    head = struct.pack(">BBIH", pr.PROTOCOL_VERSION, kind, session & 0xFFFFFFFF, seq & 0xFFFF) + body
    return head + struct.pack(">H", pr.crc16(head))


def set_fins_body(words: list[int], command: int, lease_ms: int, deadline: int, boot: int) -> bytes:
    return struct.pack(">8H", *words) + struct.pack(">HHII", command & 0xFFFF, lease_ms & 0xFFFF,
                                                    deadline & 0xFFFFFFFF, boot & 0xFFFFFFFF)


class _Pc:
    """One PC's session: its address, sequence and command numbering, its last frames (for replays)."""

    def __init__(self, rng: np.random.Generator):
        self.session = 0 if rng.random() < 0.03 else int(rng.integers(0, 2**32))
        self.address = int(rng.integers(1, 2**63))
        self.seq = int(rng.choice([rng.integers(0, 65536), 65530, 0]))
        self.command = int(rng.choice([rng.integers(0, 65536), 65533]))
        self.words = [1571, 300, 1000, 1000] * 2
        self.frames: list[bytes] = []

    def frame(self, rf: bytes, rng: np.random.Generator) -> bytes:
        raw = xb.encode_frame(xb.tx_request(rf) if rng.random() < 0.03 else xb.rx_packet(rf, self.address))
        self.frames.append(raw)
        return raw


def _pattern(rng: np.random.Generator, last: list[int]) -> list[int]:
    roll = rng.random()
    if roll < 0.1:
        return list(last)
    if roll < 0.2:  # small changes: within the rate rule's reach or just beyond
        return [int(np.clip(w + rng.integers(-200, 201), 0, 65535)) for w in last]
    fin = [int(rng.integers(0, 3300)), int(rng.choice([0, rng.integers(0, 1700)])),
           int(rng.choice([1000, 500, 800, rng.integers(50, 5500)])),
           int(rng.choice([1000, 2000, rng.integers(100, 7000)]))]
    other = fin if rng.random() < 0.4 else [int(rng.integers(0, 3300)), int(rng.integers(0, 1700)),
                                             int(rng.integers(300, 5000)), int(rng.integers(300, 7000))]
    return fin + other


def generate(seed: int) -> Stream:
    """One random stream (1-3 s of ticks and traffic), reproducible from ``seed``."""
    rng = np.random.default_rng(seed)
    boot = int(rng.integers(1, 2**32))
    uptime0 = int(rng.choice([0, 0, rng.integers(0, 2**32), 2**32 - int(rng.integers(1, 3000))]))
    clock0 = int(rng.choice([0, rng.integers(0, 2**32), 2**32 - int(rng.integers(1, 3000))]))
    s = Stream(seed, boot, uptime0, clock0)
    pcs = [_Pc(rng) for _ in range(3)]
    if rng.random() < 0.4:
        return _calm(rng, s, pcs[0])
    main, retired = 0, []
    end = int(rng.integers(1000, 3000))
    t, silent_until, pending = 0, -1, b""
    gap_kind = rng.random()
    while t < end:
        t += int(rng.choice([10] * 12 + [1, 5, 9, 11, 15, 20, 30, 45])) if gap_kind < 0.7 else 10
        if rng.random() < 0.004:
            silent_until = t + int(rng.integers(200, 900))  # the PC goes quiet: watchdog, lease
        s.events.append((t, "tick", None))
        if s.reboot is None and rng.random() < 0.001:
            s.reboot = (t + 1, int(rng.integers(1, 2**32)))
            s.events.append((t + 1, "reboot", s.reboot[1]))
            t += 1
        if t < silent_until or rng.random() > 0.45:
            continue
        at = t + int(rng.choice([0, 0, rng.integers(0, 10)]))
        raw = b""
        for _ in range(int(rng.choice([1, 1, 1, 2, 3]))):
            raw += _traffic(rng, s, pcs, main, retired, at)
            if rng.random() < 0.04:  # a takeover: the claimer commands from now on
                main = (main + 1) % 3
                retired.append(main)
        raw = pending + raw
        pending = b""
        if len(raw) > 2 and rng.random() < 0.1:
            cut = int(rng.integers(1, len(raw)))
            raw, pending = raw[:cut], raw[cut:]
        s.events.append((at, "rx", raw))
        t = max(t, at)
    return s


def _calm(rng: np.random.Generator, s: Stream, pc: _Pc) -> Stream:
    """A controller at work: a new command every 0.5 s, keep-alive copies every 0.1 s, deadlines 0.95 s ahead.

    The fins run for seconds: many turning points, the rate rule and the transition's stretch at work.
    """
    end, t = int(rng.integers(2000, 5000)), 0
    jitter = int(rng.choice([0, 3, 9]))
    k = 0
    while t < end:
        t += 10
        s.events.append((t, "tick", None))
        if t % 100 != 50:
            continue
        at = t + int(rng.integers(0, jitter + 1))
        pc.seq += 1
        if k % 5 == 0:
            pc.command += 1
            pc.words = _pattern(rng, pc.words)
        k += 1
        deadline = (_uptime(s, at) + 950) & 0xFFFFFFFF
        body = set_fins_body(pc.words, pc.command, 800, deadline or 1, s.boot)
        raw = pc.frame(message(pr.MsgType.SET_FINS, pc.session, pc.seq, body), rng)
        if rng.random() < 0.03:
            raw = bytes(rng.integers(0, 256, 12).astype(np.uint8).tobytes()) + raw  # line noise before it
        s.events.append((at, "rx", raw))
        if at > t:  # a read between ticks: the next tick comes after it
            s.events.append((t + 10, "tick", None))
            t += 10
    return s


def _uptime(s: Stream, t: int) -> int:
    if s.reboot is not None and t >= s.reboot[0]:
        return t - s.reboot[0]
    return (s.uptime0 + t) & 0xFFFFFFFF


def _current_boot(s: Stream, t: int) -> int:
    return s.reboot[1] if s.reboot is not None and t >= s.reboot[0] else s.boot


def _traffic(rng: np.random.Generator, s: Stream, pcs: list[_Pc], main: int, retired: list[int], at: int) -> bytes:
    """One frame (or garbage) at time ``at``."""
    roll = rng.random()
    pc = pcs[main]
    if roll < 0.45:  # a new command, sometimes a copy or an older one
        pc.seq += 1
        c = rng.random()
        pc.command += 1 if c < 0.8 else 0 if c < 0.9 else -int(rng.integers(1, 5)) if c < 0.95 else 40000
        if c < 0.8 or rng.random() < 0.5:
            pc.words = _pattern(rng, pc.words)
        lease = int(rng.choice([800, 800, 1000, rng.integers(1, 1001), 0, 1001, 65535],
                               p=[.4, .1, .1, .3, .03, .04, .03]))
        d = rng.random()
        deadline, boot = 0, 0
        if d > 0.4:
            boot = _current_boot(s, at) if d < 0.95 else int(rng.integers(1, 2**32))
            ahead = int(rng.choice([rng.integers(-50, 1200), rng.integers(-2, 3), 0, 1]))
            deadline = (_uptime(s, at) + ahead) & 0xFFFFFFFF
            if deadline == 0:
                deadline = 1
        body = set_fins_body(pc.words, pc.command, lease, deadline, boot)
        return pc.frame(message(pr.MsgType.SET_FINS, pc.session, pc.seq, body), rng)
    if roll < 0.55:
        pc.seq += 1
        kind = int(rng.choice([pr.MsgType.HEARTBEAT, pr.MsgType.STOP, pr.MsgType.CLAIM], p=[0.7, 0.2, 0.1]))
        return pc.frame(message(kind, pc.session, pc.seq), rng)
    if roll < 0.62 and pc.frames:  # a duplicate or a stale replay
        return pc.frames[-1] if rng.random() < 0.6 else pc.frames[int(rng.integers(0, len(pc.frames)))]
    if roll < 0.75:  # another session: refused, a STOP, a CLAIM, or a retired one's
        other = pcs[int(rng.choice([i for i in range(3) if i != main]))]
        other.seq += int(rng.choice([1, 1, 0, -3]))
        kind = int(rng.choice([pr.MsgType.HEARTBEAT, pr.MsgType.STOP, pr.MsgType.CLAIM, pr.MsgType.SET_FINS],
                              p=[0.3, 0.3, 0.2, 0.2]))
        body = set_fins_body(other.words, other.command + 1, 800, 0, 0) if kind == pr.MsgType.SET_FINS else b""
        if kind == pr.MsgType.SET_FINS:
            other.command += 1
        return other.frame(message(kind, other.session, other.seq, body), rng)
    if roll < 0.8:  # the robot's own kinds, another XBee frame type
        r = rng.random()
        if r < 0.4:
            return xb.encode_frame(xb.rx_packet(message(pr.MsgType.STATUS, pc.session, 1, bytes(23)), pc.address))
        if r < 0.7:
            return xb.encode_frame(xb.rx_packet(message(pr.MsgType.LATCH, pc.session, 1, bytes(20)), pc.address))
        return xb.encode_frame(bytes((0x8B, 1, 0xFF, 0xFE, 0, 0, 0)))
    # damage: garbage, bit flips, truncation, length lies, escape abuse
    pc.seq += 1
    good = bytearray(pc.frame(message(pr.MsgType.HEARTBEAT, pc.session, pc.seq), rng) if rng.random() < 0.5 else
                     pc.frame(message(pr.MsgType.SET_FINS, pc.session, pc.seq,
                                      set_fins_body(pc.words, pc.command, 800, 0, 0)), rng))
    pc.frames.pop()
    r = rng.random()
    if r < 0.15:  # a damaged message in an intact frame: only the CRC-16 catches it
        rf = bytearray(message(pr.MsgType.HEARTBEAT, pc.session, pc.seq))
        rf[int(rng.integers(0, len(rf)))] ^= 1 << int(rng.integers(0, 8))
        return xb.encode_frame(xb.rx_packet(bytes(rf), pc.address))
    if r < 0.35:
        i = int(rng.integers(1, len(good)))
        good[i] ^= 1 << int(rng.integers(0, 8))
    elif r < 0.5:
        good = good[:int(rng.integers(1, len(good)))]
    elif r < 0.6:
        good[1:3] = struct.pack(">H", int(rng.choice([0, 300, len(good) + 5])))
    elif r < 0.7:
        good.insert(int(rng.integers(1, len(good))), 0x7D)
    else:
        good = bytearray(rng.integers(0, 256, int(rng.integers(1, 40))).astype(np.uint8).tobytes())
    return bytes(good)
