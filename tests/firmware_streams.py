"""Generated message streams and the two robots they drive: the Python reference and the C firmware core.

Helper of ``tests/test_firmware_differential.py`` (the float32 bound and the comparison rules are argued there).
A :class:`Stream` is a list of events on the robot's millisecond clock (ticks, received bytes, reboots);
:class:`ReferenceRobot` runs them through :class:`~pectoral_gym.hardware.radio.firmware.Firmware` and a one-fish
model's fins as the emulator does (``advance_with_firmware``'s tick-then-advance, ``apply_firmware`` after each
tick and each read), :class:`CRobot` through :class:`~pectoral_gym.hardware.radio.cfirmware.CFirmware`. Both
return, per event, a :class:`Snapshot`: the RF messages the robot sent (with their destination), the latches and
halts of the fins, the state and counters and the fins' half-strokes.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field

import numpy as np

from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio import xbee as xb
from pectoral_gym.hardware.radio.cfirmware import CFirmware
from pectoral_gym.hardware.radio.firmware import Firmware
from pectoral_gym.model import strokes
from pectoral_gym.model.finrules import FirmwareConfig, apply_firmware, latched, stroke_kinds
from pectoral_gym.model.spec import FULL_FAST

IGNORED = ("duplicate", "stale", "retired", "refused", "copy", "bad_lease", "late", "boot", "foreign_stop")
DECODER = ("frames", "messages", "skipped_bytes", "framing_errors", "truncated", "checksum_errors", "crc_errors",
           "malformed", "other_frames")


@dataclass
class Stream:
    """Events ``(t_ms, kind, data)``: ``tick``, ``rx`` (bytes), ``reboot`` (new boot id); clock = ``clock0 + t``."""

    seed: int
    boot: int
    uptime0: int  # uptime [ms] at t = 0 (near 2**32: the uptime wraps within the stream)
    clock0: int  # the C clock at t = 0 (near 2**32: the clock wraps)
    reboot: tuple[int, int] | None = None  # (t, new boot id) of a power-up within the stream
    events: list[tuple[int, str, object]] = field(default_factory=list)


@dataclass
class Snapshot:
    """What one event did: ``tx`` [(dest64, rf bytes)], ``latches`` [(t_ms float, fin, power, still, turn,
    pattern (bias, amp, period s, ratio))], ``halts`` [angles], ``info`` (state, counters), ``fins`` ``(2, 10)``:
    from, to, duration [s], elapsed [s], power, bias, amplitude, period [s], ratio, angle."""

    tx: list[tuple[int, bytes]]
    latches: list[tuple]
    halts: list[tuple[float, float]]
    info: dict[str, int]
    fins: np.ndarray


# ---------------------------------------------------------------- the reference
class _AddressedDecoder(pr.StreamDecoder):
    """StreamDecoder that also returns each message's sender address (broadcast for a Transmit Request)."""

    def _check(self, out: list) -> None:
        before, buf = len(out), bytes(self._buf)
        super()._check(out)
        if len(out) > before:
            data = buf[2:-1]
            src = int.from_bytes(data[1:9], "big") if data[0] == xb.RX_PACKET else xb.BROADCAST
            out[-1] = (out[-1], src)


class ReferenceRobot:
    """The Python reference: :class:`Firmware` and a one-fish model's fins, driven as the emulator drives them."""

    _model = None

    def __init__(self, config: FirmwareConfig, boot: int, uptime0: int):
        if ReferenceRobot._model is None:
            ReferenceRobot._model = FULL_FAST.build(1)
        self.model = ReferenceRobot._model
        self.config = config
        self.t_ms = 0
        self._power_up(boot, -uptime0 / 1000.0)

    def _power_up(self, boot: int, power_up: float) -> None:
        self.fw = Firmware(self.config, boot=boot, power_up=power_up)
        self.decoder = _AddressedDecoder()
        self.model.reset()  # fins at rest at 90 deg
        self.model.time = self.t_ms / 1000.0
        self.address = xb.BROADCAST

    def _advance(self, t_ms: int, tx: list, latches: list) -> None:
        if t_ms <= self.t_ms:
            return
        kinds = stroke_kinds(self.model)
        before = self.model.fins[0].copy()
        start = self.model.time
        self.model.advance(t_ms / 1000.0 - self.model.time)
        self.model.time, self.t_ms = t_ms / 1000.0, t_ms
        fins = self.model.fins[0]
        # A fin latches where its half-stroke in progress ends (at once if it was over). ``latched`` reads the time
        # back from ELAPSED, which stands still for a fin that then holds idle (``stepping.advance_one``).
        ends = start + np.maximum(before[:, strokes.DURATION] - before[:, strokes.ELAPSED], 0.0)
        flipped = sorted((ends[fin], fin) for fin, _ in latched(self.model, kinds))
        for t, fin in sorted(flipped, key=lambda tf: (round(tf[0], 9), tf[1])):
            stroke = fins[fin]
            beat = stroke[strokes.BIAS:strokes.RATIO + 1].copy()
            power = bool(stroke[strokes.POWER] > 0.5)
            still = bool(stroke[strokes.ANGLE_FROM] == stroke[strokes.ANGLE_TO])
            latches.append((round(t * 1000.0, 6), fin, power, still, float(stroke[strokes.ANGLE_FROM]),
                            tuple(float(v) for v in beat)))
            report = self.fw.latch_report(round(t, 9), fin, beat, stroke[strokes.ANGLE_FROM], power)
            if report is not None:
                tx.append((self.address, pr.encode_message(report)))

    def _apply(self, halts: list) -> None:
        if self.fw.halt:
            halts.append(tuple(float(a) for a in self.model.fin_angles()[0][0]))
        apply_firmware(self.fw, self.model)

    def step(self, t_ms: int, kind: str, data: object) -> Snapshot:
        """Run one event."""
        tx, latches, halts = [], [], []
        now = t_ms / 1000.0
        self._advance(t_ms, tx, latches)
        if kind == "tick":
            self.fw.tick(now, self.model.fin_angles()[0][0])
            self._apply(halts)
        elif kind == "rx":
            messages = self.decoder.feed(data)
            self.fw.crc_errors = self.decoder.crc_errors + self.decoder.checksum_errors
            for msg, src in messages:
                tracker, new = self.fw.tracker, self.fw.tracker.new
                reply = self.fw.receive(msg, now)
                if self.fw.session == msg.session and (self.fw.tracker is not tracker or self.fw.tracker.new > new):
                    self.address = src  # the served session's last new message
                if reply is not None:
                    tx.append((src, pr.encode_message(reply)))
            self._apply(halts)
        elif kind == "reboot":
            self._power_up(int(data), now)
        return Snapshot(tx, latches, halts, self.info(), self.fins())

    def info(self) -> dict[str, int]:
        fw = self.fw
        info = {"state": int(fw.state), "session": fw.session, "command_id": fw.command_id,
                "clipped": int(fw.clipped), **fw.ignored}
        info.update({name: getattr(self.decoder, name) for name in DECODER})
        return info

    def fins(self) -> np.ndarray:
        fins = self.model.fins[0]
        out = np.zeros((2, 10))
        out[:, :9] = fins[:, [strokes.ANGLE_FROM, strokes.ANGLE_TO, strokes.DURATION, strokes.ELAPSED, strokes.POWER,
                              strokes.BIAS, strokes.AMPLITUDE, strokes.PERIOD, strokes.RATIO]]
        out[:, 9] = self.model.fin_angles()[0][0]
        return out


# ---------------------------------------------------------------- the C core
def split_frames(raw: bytes) -> list[tuple[int, bytes]]:
    """``(dest64, rf data)`` of the robot's Transmit Request frames; raises if any is not one (frame id 0)."""
    out, start = [], 0
    while start < len(raw):
        end = raw.find(bytes((xb.START,)), start + 1)
        end = len(raw) if end < 0 else end
        data = xb.decode_frame(raw[start:end])
        if data[0] != xb.TX_REQUEST or data[1] != 0 or data[10:14] != b"\xff\xfe\x00\x00":
            raise AssertionError(f"not a Transmit Request with frame id 0: {data[:14].hex()}")
        out.append((int.from_bytes(data[2:10], "big"), data[14:]))
        start = end
    return out


class CRobot:
    """The C core through the binding, on the clock ``clock0 + t``."""

    def __init__(self, config: FirmwareConfig, boot: int, uptime0: int, clock0: int, variant: str | None = None):
        self.config, self.clock0, self.variant = config, clock0, variant
        self.fw = CFirmware(config, boot, (clock0 - uptime0) & 0xFFFFFFFF, variant)

    def step(self, t_ms: int, kind: str, data: object) -> Snapshot:
        clock = (self.clock0 + t_ms) & 0xFFFFFFFF
        if kind == "tick":
            self.fw.tick(clock)
        elif kind == "rx":
            self.fw.receive_bytes(data, clock)
        events, raw = [], b""
        if kind == "reboot":
            self.fw.receive_bytes(b"", clock)  # the fins run to the brown-out (and report), then the power-up
            events, raw = self.fw.take_events(), self.fw.take_tx()
            self.fw = CFirmware(self.config, int(data), clock, self.variant)
        latches, halts = [], []
        for ev in events + self.fw.take_events():
            t = ((ev.ms - self.clock0) & 0xFFFFFFFF) + ev.frac_ms
            if ev.kind == "latch":
                latches.append((t, ev.fin, ev.power, ev.still, ev.turn, ev.pattern))
            else:
                halts.append(ev.angles)
        return Snapshot(split_frames(raw + self.fw.take_tx()), latches, halts, self.info(), self.fins())

    def info(self) -> dict[str, int]:
        raw = self.fw.info()
        info = {"state": raw["state"], "session": raw["session"] if raw["has_session"] else None,
                "command_id": raw["command_id"] if raw["has_command_id"] else None, "clipped": raw["clipped"]}
        info.update({name: raw["boot_mismatch" if name == "boot" else name] for name in IGNORED})
        info.update({name: raw[name] for name in DECODER})
        return info

    def fins(self) -> np.ndarray:
        out = np.zeros((2, 10))
        for f in range(2):
            r = self.fw.raw_fin(f).astype(float)
            out[f] = (r[0], r[1], r[2] / 1000.0, r[3] / 1000.0, r[4], r[5], r[6], r[7] / 1000.0, r[8], r[9])
        return out


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


def angle_bound(stroke_from: float, stroke_to: float, duration: float, time_error: float) -> float:
    """Largest angle difference [rad] the float32 arguments of the module docstring allow for a half-stroke."""
    peak = math.pi * abs(stroke_to - stroke_from) / (2.0 * max(duration, 1e-9))
    return ANGLE_ABS + peak * time_error


ANGLE_ABS = 4e-6  # rad, see tests/test_firmware_differential.py
