"""The emulated robot's dsPIC: the robot's rules driving the physics model's fins, behind one small interface.

:class:`pectoral_gym.hardware.emulator.EmulatedRobot` runs either of two implementations of the rules:

* :class:`PythonFirmware` (the default, and the specification): the reference state machine
  :class:`pectoral_gym.hardware.radio.firmware.Firmware`, which hands its setpoint to the model's own fins
  (:func:`pectoral_gym.model.finrules.apply_firmware`), ticked before every :data:`CHUNK` of the model;
* :class:`CFirmwareAdapter`: the robot's C firmware core through its binding
  (:class:`pectoral_gym.hardware.radio.cfirmware.CFirmware`), fed what the robot's XBee would deliver and ticked
  every 10 ms of emulated time; the model's fins follow the C fins' latches and halts.

Both satisfy :class:`RobotFirmware`: ``receive`` takes the bytes from the PC's radio (the PC's XBee sends
Transmit Requests, ``0x10``) and returns the escaped Receive Packet frames (``0x90``) the PC's XBee hands the PC;
``advance`` runs the rules and the model to a time and returns the frames sent meanwhile (LATCH reports);
``reboot`` is a power-up. Call them with the emulator's lock held.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any, Protocol

import numpy as np

from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio import xbee as xb
from pectoral_gym.hardware.radio.firmware import MS_GUARD, Firmware
from pectoral_gym.model import strokes
from pectoral_gym.model.finrules import CHUNK, FirmwareConfig, apply_firmware, force_latch, latched, stroke_kinds
from pectoral_gym.model.models import FishModel
from pectoral_gym.model.params import FinBeat

__all__ = ["ROBOT_ADDRESS", "PC_ADDRESS", "FIRMWARES", "RobotFirmware", "PythonFirmware", "CFirmwareAdapter",
           "make_firmware", "trace_entry"]

ROBOT_ADDRESS = 0x0013A20000000001  # 64-bit source address the emulated XBee reports
PC_ADDRESS = 0x0013A20000000002  # 64-bit source address of the PC's XBee, as the robot's XBee reports it
_GRID_MS = 10  # the C firmware's tick [ms]
_EPS = 1e-9  # [s]: a model this close to a time is there (float sums of chunks)
FIRMWARES = ("python", "c", "python-10ms")  # the rules an emulated robot can run (PythonFirmware's grid: the last)


class RobotFirmware(Protocol):
    """What the emulator needs of the robot's rules (both implementations; times in emulated robot seconds).

    Attributes:
        firmware: What tests and logs inspect: ``state`` (:class:`~pectoral_gym.hardware.radio.protocol.RobotState`),
            ``running``, ``boot``.
        decoder: Counters of what was received: ``messages``, ``crc_errors``, ...
    """

    firmware: Any
    decoder: Any

    def receive(self, data: bytes, now: float, model: FishModel, keep: Callable[[], bool],
                trace: list | None) -> tuple[list[bytes], list[pr.Message]]:
        """Bytes from the PC at ``now`` (after :meth:`advance` to ``now``): frames to send back, messages heard.

        ``keep()`` is asked once per message; ``False`` drops it (the emulator's loss injection).
        """
        ...

    def advance(self, model: FishModel, target: float, trace: list | None) -> list[bytes]:
        """Run the rules and the model to ``target``; returns the frames sent meanwhile (LATCH reports)."""
        ...

    def reboot(self, now: float, model: FishModel, boot: int) -> None:
        """A power-up at ``now`` with boot id ``boot``: fins halt where they are, state IDLE, uptime from 0."""
        ...


def to_pc(payload: bytes) -> bytes:
    """The escaped Receive Packet frame the PC's XBee hands the PC for RF data ``payload`` from the robot."""
    return xb.encode_frame(xb.rx_packet(payload, ROBOT_ADDRESS))


def trace_entry(model: FishModel, running: bool) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, bool]:
    """``(t, state (6,), fin rates (2,), peak rates of the half-strokes in progress (2,), running)`` of fish 0."""
    fins = model.fins[0]
    peak = math.pi * np.abs(fins[:, strokes.ANGLE_TO] - fins[:, strokes.ANGLE_FROM]) / (
        2.0 * np.maximum(fins[:, strokes.DURATION], 1e-9))  # stroke_kinematics' peak |g'|
    return (model.time, model.state[0].copy(), model.fin_angles()[1][0].copy(), peak, running)


class PythonFirmware:
    """The reference rules (:class:`Firmware`) on the model's own fins: the specification.

    By default the rules tick before every :data:`CHUNK` of the model, whose chunks end wherever the emulator
    wakes (a byte arriving, its 10 ms poll), and a message is heard at the emulated time it arrives. With
    ``grid`` they run as the C core is driven (:class:`CFirmwareAdapter`): ticks at every multiple of 10 ms of
    emulated time, a message heard at the whole millisecond it arrives in; the rules are the same, only when
    they act differs (by less than a tick), which is what a closed loop may amplify.

    Args:
        config: The rules' settings.
        boot: The boot id of this power-up.
        power_up: Emulated time of the power-up [s].
        grid: Tick on the 10 ms grid, as the robot (``firmware_impl="python-10ms"``).
    """

    def __init__(self, config: FirmwareConfig | None, boot: int, power_up: float = 0.0, grid: bool = False):
        self.config, self.grid = config, grid
        self.firmware = Firmware(config, boot=boot, power_up=power_up)
        self.decoder = pr.StreamDecoder()
        self._next_tick_ms = _ms(power_up)

    def receive(self, data: bytes, now: float, model: FishModel, keep: Callable[[], bool],
                trace: list | None) -> tuple[list[bytes], list[pr.Message]]:
        """See :meth:`RobotFirmware.receive`: decoded, handed to the rules, the fins handed their patterns."""
        frames: list[bytes] = []
        if self.grid:  # heard at the whole ms, the fins run there first (as pfw_receive does)
            now = max(_ms(now) / 1000.0, model.time)
            frames = self._run_model(model, now, trace)
        messages = [m for m in self.decoder.feed(data) if keep()]
        self.firmware.crc_errors = self.decoder.crc_errors + self.decoder.checksum_errors
        replies = [self.firmware.receive(m, now) for m in messages]
        apply_firmware(self.firmware, model)
        return frames + [to_pc(pr.encode_message(r)) for r in replies if r is not None], messages

    def advance(self, model: FishModel, target: float, trace: list | None) -> list[bytes]:
        """See :meth:`RobotFirmware.advance`: a tick before every :data:`CHUNK` of the model (or on the grid)."""
        frames: list[bytes] = []
        if self.grid:
            while self._next_tick_ms <= _ms(target):
                frames += self._run_model(model, self._next_tick_ms / 1000.0, trace)
                self.firmware.tick(self._next_tick_ms / 1000.0, model.fin_angles()[0][0])
                apply_firmware(self.firmware, model)
                self._next_tick_ms += _GRID_MS
            return frames
        while model.time < target:
            self.firmware.tick(model.time, model.fin_angles()[0][0])
            apply_firmware(self.firmware, model)
            kinds = stroke_kinds(model)
            model.advance(min(CHUNK, target - model.time))
            frames += self._latch_reports(model, kinds)
            if trace is not None:
                trace.append(trace_entry(model, self.firmware.running))
        return frames

    def _run_model(self, model: FishModel, until: float, trace: list | None) -> list[bytes]:
        """The model (no tick) to ``until`` [s]; the LATCH frames of its latches meanwhile."""
        frames: list[bytes] = []
        while model.time < until - _EPS:
            kinds = stroke_kinds(model)
            model.advance(min(CHUNK, until - model.time))
            frames += self._latch_reports(model, kinds)
            if trace is not None:
                trace.append(trace_entry(model, self.firmware.running))
        return frames

    def _latch_reports(self, model: FishModel, kinds: np.ndarray) -> list[bytes]:
        """LATCH frames for the fins that latched in the last advance: the servo controller reports them at once."""
        frames = []
        for fin, t in latched(model, kinds):
            stroke = model.fins[0, fin]
            report = self.firmware.latch_report(round(t, 9), fin, stroke[strokes.BIAS:strokes.RATIO + 1],
                                                stroke[strokes.ANGLE_FROM], stroke[strokes.POWER] > 0.5)
            if report is not None:
                frames.append(to_pc(pr.encode_message(report)))
        return frames

    def reboot(self, now: float, model: FishModel, boot: int) -> None:
        """See :meth:`RobotFirmware.reboot`."""
        self.firmware = Firmware(self.config, boot=boot, power_up=now)
        self.firmware.halt = True  # the servos hold where the brown-out left them
        self.decoder = pr.StreamDecoder()  # a frame half received is lost
        apply_firmware(self.firmware, model)




class CFirmwareAdapter:
    """The C firmware core as the emulated robot's dsPIC; the model's fins follow the C fins.

    The robot's XBee turns the PC's Transmit Requests into Receive Packets (from :data:`PC_ADDRESS`) for the
    core, and the core's Transmit Requests into Receive Packets to the PC; frames the PC's XBee would not send
    (a bad checksum, another frame type) never reach the core. The core's clock is the emulated time in whole ms;
    it is ticked at every multiple of 10 ms. After each call the model runs to each latch or halt the core
    reports, at its time, and applies it: a latch starts the reported half-stroke
    (:func:`pectoral_gym.model.finrules.force_latch`), a halt rests both fins at the core's angles. The
    model thus lags the core by less than a tick between its calls.

    Args:
        config: The rules' settings (passed to the core).
        boot: The boot id of this power-up.
        variant: ``None``, or a deliberately broken build (``pectoral_gym.hardware.radio.cfirmware.VARIANTS``).
        power_up: Emulated time of the power-up [s].
    """

    def __init__(self, config: FirmwareConfig | None, boot: int, variant: str | None = None, power_up: float = 0.0):
        from pectoral_gym.hardware.radio.cfirmware import CFirmware
        from pectoral_gym.hardware.radio.radioproxy import FrameSplitter

        self.config, self.variant = config, variant
        self.core = CFirmware(config, boot=boot, power_up_ms=_ms(power_up), variant=variant)
        self.firmware = self  # what tests inspect: state, running, boot, ignored
        self._splitter, self._tx_splitter = FrameSplitter(), FrameSplitter()
        self._next_tick_ms = _ms(power_up)

    # ------------------------------------------------------------ what tests and logs read
    @property
    def state(self) -> pr.RobotState:
        """The core's state."""
        return pr.RobotState(self.core.state)

    @property
    def running(self) -> bool:
        """Whether the fins beat."""
        return self.core.state == pr.RobotState.RUNNING

    @property
    def boot(self) -> int:
        """This power-up's boot id."""
        return self.core.boot

    @property
    def ignored(self) -> dict[str, int]:
        """Messages not acted on, by reason (as :attr:`Firmware.ignored`)."""
        info = self.core.info()
        names = ("duplicate", "stale", "retired", "refused", "copy", "bad_lease", "late", "foreign_stop")
        return {**{n: info[n] for n in names}, "boot": info["boot_mismatch"]}

    @property
    def decoder(self) -> SimpleNamespace:
        """The core's decoder counters (``messages``, ``crc_errors``, ...)."""
        info = self.core.info()
        names = ("frames", "messages", "skipped_bytes", "framing_errors", "truncated", "checksum_errors",
                 "crc_errors", "malformed", "other_frames")
        return SimpleNamespace(**{n: info[n] for n in names})

    # ------------------------------------------------------------ RobotFirmware
    def receive(self, data: bytes, now: float, model: FishModel, keep: Callable[[], bool],
                trace: list | None) -> tuple[list[bytes], list[pr.Message]]:
        """See :meth:`RobotFirmware.receive`: re-framed as the robot's XBee delivers it, at the ms ``now`` is in."""
        frames, messages = [], []
        for unit in self._splitter.feed(data):
            try:
                frame = xb.decode_frame(unit)
            except xb.ProtocolError:
                continue  # garbage or a damaged frame: the PC's XBee sends nothing
            if frame[0] != xb.TX_REQUEST or (payload := xb.rf_data(frame)) is None or not keep():
                continue
            try:
                messages.append(pr.decode_message(payload))  # the record; the core decodes for itself
            except xb.ProtocolError:
                pass
            frames.append(xb.encode_frame(xb.rx_packet(payload, PC_ADDRESS)))
        if not frames:
            return [], messages
        now_ms = max(_ms(now), self._next_tick_ms - _GRID_MS)  # never before the core's last tick
        self.core.receive_bytes(b"".join(frames), now_ms)
        self._follow(model, now_ms, trace)
        return self._sent(), messages

    def advance(self, model: FishModel, target: float, trace: list | None) -> list[bytes]:
        """See :meth:`RobotFirmware.advance`: a tick at every multiple of 10 ms up to ``target``."""
        while self._next_tick_ms <= _ms(target):
            self.core.tick(self._next_tick_ms)
            self._follow(model, self._next_tick_ms, trace)
            self._next_tick_ms += _GRID_MS
        return self._sent()

    def reboot(self, now: float, model: FishModel, boot: int) -> None:
        """See :meth:`RobotFirmware.reboot`; the core powers up with its fins at rest at 90 deg, so does the model."""
        from pectoral_gym.hardware.radio.cfirmware import CFirmware

        self.core = CFirmware(self.config, boot=boot, power_up_ms=_ms(now), variant=self.variant)
        self._splitter = type(self._splitter)()  # a frame half received is lost; one half sent too
        self._tx_splitter = type(self._tx_splitter)()
        _rest(model, self.core.fin_angles())

    # ------------------------------------------------------------ the model follows the core
    def _sent(self) -> list[bytes]:
        """The core's Transmit Requests, as the PC's XBee hands them to the PC."""
        out = []
        for unit in self._tx_splitter.feed(self.core.take_tx()):
            payload = xb.rf_data(xb.decode_frame(unit))
            if payload is not None:
                out.append(to_pc(payload))
        return out

    def _follow(self, model: FishModel, until_ms: int, trace: list | None) -> None:
        """Run the model through the core's latches and halts since the last call, then to ``until_ms``."""
        running = self.running
        for event in self.core.take_events():
            t = (event.ms + event.frac_ms) / 1000.0
            _run_model(model, t, trace, running)
            if event.kind == "halt":
                _rest(model, np.asarray(event.angles))
            else:
                force_latch(model, event.fin, t, np.asarray(event.pattern), event.turn, event.power)
                pending = self.core.raw_fin(event.fin)[10:14].astype(float)
                if pending[2] > 0:  # what the fin latches next, should the model reach its turning point first
                    model.pending[0, event.fin] = (*pending[:2], pending[2] / 1000.0, pending[3])
        _run_model(model, until_ms / 1000.0, trace, running)


def _ms(t: float) -> int:
    """Emulated time ``t`` [s] as the core's whole-ms clock (a hair below a whole ms counts as it)."""
    return int(math.floor(1000.0 * t + MS_GUARD))


def _run_model(model: FishModel, until: float, trace: list | None, running: bool) -> None:
    """Advance the model to ``until`` [s] in chunks of at most :data:`CHUNK`."""
    while model.time < until - _EPS:
        model.advance(min(CHUNK, until - model.time))
        if trace is not None:
            trace.append(trace_entry(model, running))


def _rest(model: FishModel, angles: np.ndarray) -> None:
    """Both fins of fish 0 held still at ``angles`` [rad] from now (a halt, as ``apply_firmware`` does)."""
    time_now = model.time
    model.reset(model.state.copy(), right=FinBeat.rest(float(angles[0])), left=FinBeat.rest(float(angles[1])),
                index=np.arange(1))
    model.time = time_now


def make_firmware(impl: str, config: FirmwareConfig | None, boot: int, variant: str | None = None) -> RobotFirmware:
    """The rules an emulated robot runs: ``impl`` ``"python"`` (reference) or ``"c"`` (``variant``: a broken build)."""
    if impl in ("python", "python-10ms"):
        if variant is not None:
            raise ValueError("a firmware variant is a build of the C firmware: it needs --firmware c")
        return PythonFirmware(config, boot, grid=impl == "python-10ms")
    if impl == "c":
        return CFirmwareAdapter(config, boot, variant=variant)
    raise ValueError(f"firmware_impl must be one of {', '.join(FIRMWARES)}, got {impl!r}")
