"""The simulated ATmega2560 as the emulated robot's microcontroller: its fins drive the emulated physics.

:class:`SimavrCore` has the methods of :class:`pectoral_gym.hardware.radio.cfirmware.CFirmware` that
:class:`pectoral_gym.hardware.emulated_firmware.CFirmwareAdapter` uses (``receive_bytes``, ``tick``, ``take_tx``,
``take_events``, ``raw_fin``, ``fin_angles``, ``info``, ``state``, ``boot``), backed by ``pfw_simavr --lockstep``
running the events build of the AVR port (``make -C firmware avr-events``): the bytes go to the simulated USART0
as the robot's XBee delivers them (57600 baud, so a message completes some ms after it arrives), the MCU runs on
its own 1 ms timer interrupt and ticks itself every 10 ms, and the fin events (latches, halts) and the state come
back over its USART1. :func:`simavr_adapter` puts it into a ``CFirmwareAdapter``, which re-frames the radio and
makes the model's fins follow the MCU's events, as it does for the C core in-process.

Differences from the in-process core, all on the MCU's side of the interface: replies and events come when the
simulated MCU sends them (a few ms after the bytes), so the model may pass a turning point before the MCU's latch
event reaches it; ``force_latch`` then starts the half-stroke at the event's time, up to a step late in the model.
``info()`` reports the state and boot id only (the MCU's counters stay on the MCU). The emulated time and the MCU's
clock both start at 0; ``reboot`` starts a new MCU whose clock starts then. To keep up with real time on a busy
machine, ``tick`` runs the simulator in batches of :data:`BATCH_MS` (a message still starts on the MCU at its
arrival), so replies and events reach the emulator up to that much later.
"""

from __future__ import annotations

import struct
import subprocess
import time
from pathlib import Path

import numpy as np

from pectoral_gym.hardware.radio.cfirmware import _INFO_NAMES, FinEvent

FIRMWARE = Path(__file__).resolve().parents[3]  # firmware/
EVENTS_ELF = FIRMWARE / "build" / "avr" / "pfw_avr_events.elf"
SIM = FIRMWARE / "build" / "avr" / "pfw_simavr"
_RECORD = struct.Struct("<BBBBIff4f2f4fB")  # after the 0xA5 sync byte: see main_avr.c, event_record()
_SYNC = 0xA5
BATCH_MS = 30  # tick() runs the MCU only once it is this far behind: fewer round trips, events up to this late


class SimavrCore:
    """The firmware on a simulated ATmega2560 behind the C core's binding interface (times: emulated clock ms).

    Args:
        power_up_ms: Emulated clock [ms] at which this MCU powers up (its own clock reads 0 then).
        adc_seed: Seed of the ADC noise the boot id is drawn from.
    """

    def __init__(self, power_up_ms: int = 0, adc_seed: int = 1):
        if not (EVENTS_ELF.exists() and SIM.exists()):
            raise RuntimeError("build first: make -C firmware avr-events")
        self.power_up_ms = int(power_up_ms)
        self._proc = subprocess.Popen([str(SIM), "--lockstep", "--adc-seed", str(int(adc_seed)), "--report",
                                       "/dev/null", str(EVENTS_ELF)], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, text=True, bufsize=1)
        self._tx = bytearray()
        self._events = bytearray()
        self._pending = np.zeros((2, 4), dtype=np.float32)
        self._angles = np.full(2, np.pi / 2)
        self._state, self._boot = 0, 0
        self._mcu_ms = 0
        self.calls, self.call_seconds = 0, 0.0  # round trips to the harness and the wall time they took
        self._answer()  # the harness's first answer: nothing has run yet
        self._run(0)

    # ------------------------------------------------------------ the harness
    def _answer(self) -> None:
        assert self._proc.stdout is not None
        while True:
            line = self._proc.stdout.readline()
            if not line:
                raise RuntimeError("pfw_simavr --lockstep ended")
            tag, _, data = line.rstrip("\n").partition(" ")
            if tag == "T":
                self._tx += bytes.fromhex(data)
            elif tag == "E":
                self._events += bytes.fromhex(data)
            elif tag == "K":
                return

    def _run(self, now_ms: int) -> None:
        """Run the MCU to emulated clock ``now_ms`` (never backwards)."""
        target = max(int(now_ms) - self.power_up_ms, self._mcu_ms)
        if target == self._mcu_ms and self.calls:
            return  # already there: the events and bytes so far were collected by the last run
        start = time.perf_counter()
        assert self._proc.stdin is not None
        self._proc.stdin.write(f"R {target}\n")
        self._proc.stdin.flush()
        self._mcu_ms = target
        self._answer()
        self.calls += 1
        self.call_seconds += time.perf_counter() - start

    def close(self) -> None:
        """End the simulated MCU."""
        if self._proc.poll() is None:
            try:
                assert self._proc.stdin is not None
                self._proc.stdin.write("Q\n")
                self._proc.stdin.flush()
            except (BrokenPipeError, OSError):
                pass
            try:
                self._proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self._proc.kill()

    # ------------------------------------------------------------ CFirmware's interface
    def receive_bytes(self, data: bytes, now_ms: int) -> None:
        """Bytes the robot's XBee delivers at ``now_ms``: the MCU runs to then, the bytes start on its USART0."""
        self._run(now_ms)
        assert self._proc.stdin is not None
        self._proc.stdin.write(f"B {bytes(data).hex()}\n")
        self._proc.stdin.flush()

    def tick(self, now_ms: int) -> None:
        """Let the MCU run to ``now_ms`` (it ticks itself every 10 ms of its own clock), in batches of BATCH_MS."""
        if int(now_ms) - self.power_up_ms - self._mcu_ms >= BATCH_MS:
            self._run(now_ms)

    def take_tx(self) -> bytes:
        """The escaped Transmit Request frames the MCU sent since the last call."""
        out, self._tx = bytes(self._tx), bytearray()
        return out

    def take_events(self) -> list[FinEvent]:
        """The MCU's latches and halts since the last call, oldest first, on the emulated clock."""
        events = []
        while True:
            start = self._events.find(bytes((_SYNC,)))
            if start < 0 or len(self._events) - start - 1 < _RECORD.size:
                break
            fields = _RECORD.unpack_from(self._events, start + 1)
            del self._events[:start + 1 + _RECORD.size]
            kind, fin, power, still, ms, frac, turn = fields[:7]
            pattern, angles, pending, state = fields[7:11], fields[11:13], fields[13:17], fields[17]
            self._state = state
            if kind == 0:
                self._boot = ms
                continue
            at = (ms + self.power_up_ms) & 0xFFFFFFFF
            if kind == 1:
                self._pending[fin & 1] = pending
                events.append(FinEvent("latch", at, float(frac), fin & 1, bool(power), bool(still), float(turn),
                                       (pattern[0], pattern[1], pattern[2] / 1000.0, pattern[3])))
            else:
                self._angles = np.asarray(angles, dtype=float)
                events.append(FinEvent("halt", at, float(frac), angles=(float(angles[0]), float(angles[1]))))
        return events

    def raw_fin(self, fin: int) -> np.ndarray:
        """``float32[23]`` laid out as the binding's; only ``pending`` (10:14, period in ms) is known here."""
        out = np.zeros(23, dtype=np.float32)
        out[10:14] = self._pending[fin & 1]
        out[9] = self._angles[fin & 1]
        return out

    def fin_angles(self) -> np.ndarray:
        """The angles of the last halt (90 deg at power-up) [rad]."""
        return self._angles.copy()

    def info(self) -> dict[str, int]:
        """The binding's names; state and boot id from the MCU, the counters 0 (they stay on the MCU)."""
        out = dict.fromkeys(_INFO_NAMES, 0)
        out["state"], out["boot"] = self._state, self._boot
        return out

    @property
    def state(self) -> int:
        """The MCU's robot state, as last reported."""
        return self._state

    @property
    def boot(self) -> int:
        """The MCU's boot id."""
        return self._boot


def simavr_adapter(config=None, adc_seed: int = 1):
    """A :class:`~pectoral_gym.hardware.emulated_firmware.CFirmwareAdapter` whose core is the simulated MCU."""
    from pectoral_gym.hardware.emulated_firmware import CFirmwareAdapter

    adapter = CFirmwareAdapter.__new__(CFirmwareAdapter)
    CFirmwareAdapter.__init__(adapter, config, boot=1)  # builds an in-process core: replaced below
    adapter.core = SimavrCore(0, adc_seed)
    return adapter
