"""The two robots a generated message stream drives: the Python reference and the C firmware core.

Helper of ``tests/test_firmware_differential.py`` (the streams: ``tests/firmware_streams.py``).
:class:`ReferenceRobot` runs a stream's events through :class:`~pectoral_gym.hardware.radio.firmware.Firmware` and a
one-fish model's fins as the emulator does (``advance_with_firmware``'s tick-then-advance, ``apply_firmware`` after
each tick and each read), :class:`CRobot` through :class:`~pectoral_gym.hardware.radio.cfirmware.CFirmware`. Both
return, per event, a :class:`Snapshot`: the RF messages the robot sent (with their destination), the latches and
halts of the fins, the state and counters and the fins' half-strokes.
"""

from __future__ import annotations

from dataclasses import dataclass

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
