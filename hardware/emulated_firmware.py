"""The emulated robot's dsPIC: the robot's rules driving the physics model's fins, behind one small interface.

:class:`pectoral_gym.hardware.emulator.EmulatedRobot` runs either of two implementations of the rules:

* :class:`PythonFirmware` (the default, and the specification): the reference state machine
  :class:`pectoral_gym.hardware.radio.firmware.Firmware`, which hands its setpoint to the model's own fins
  (:func:`pectoral_gym.hardware.finreplay.apply_firmware`), ticked before every :data:`CHUNK` of the model;
* :class:`CFirmware` (:mod:`pectoral_gym.hardware.emulated_cfirmware`): the robot's C firmware core through its
  binding, fed the bytes the robot's XBee would deliver, its fins followed by the model.

Both satisfy :class:`RobotFirmware`: ``receive`` takes the bytes from the PC's radio (the PC's XBee sends
Transmit Requests, ``0x10``) and returns the escaped Receive Packet frames (``0x90``) the PC's XBee hands the PC;
``advance`` runs the rules and the model to a time and returns the frames sent meanwhile (LATCH reports);
``reboot`` is a power-up. Call them with the emulator's lock held.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from pectoral_gym.hardware.finreplay import CHUNK, apply_firmware, latched, stroke_kinds
from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio import xbee as xb
from pectoral_gym.hardware.radio.firmware import Firmware, FirmwareConfig
from pectoral_gym.model import strokes
from pectoral_gym.model.models import FishModel

__all__ = ["ROBOT_ADDRESS", "FIRMWARES", "RobotFirmware", "PythonFirmware", "make_firmware", "trace_entry"]

ROBOT_ADDRESS = 0x0013A20000000001  # 64-bit source address the emulated XBee reports
FIRMWARES = ("python", "c")  # the implementations an emulated robot can run


class RobotFirmware(Protocol):
    """What the emulator needs of the robot's rules (both implementations; times in emulated robot seconds).

    Attributes:
        firmware: What tests and logs inspect: ``state`` (:class:`~pectoral_gym.hardware.radio.protocol.RobotState`),
            ``running``, ``boot``.
        decoder: Counters of what was received: ``messages``, ``crc_errors``, ...
    """

    firmware: Any
    decoder: Any

    def receive(self, data: bytes, now: float, model: FishModel,
                keep: Callable[[], bool]) -> tuple[list[bytes], list[pr.Message]]:
        """Bytes from the PC at ``now`` (the model is there): frames to send back, and the messages acted on.

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

    Args:
        config: The rules' settings.
        boot: The boot id of this power-up.
        power_up: Emulated time of the power-up [s].
    """

    def __init__(self, config: FirmwareConfig | None, boot: int, power_up: float = 0.0):
        self.config = config
        self.firmware = Firmware(config, boot=boot, power_up=power_up)
        self.decoder = pr.StreamDecoder()

    def receive(self, data: bytes, now: float, model: FishModel,
                keep: Callable[[], bool]) -> tuple[list[bytes], list[pr.Message]]:
        """See :meth:`RobotFirmware.receive`: decoded, handed to the rules, the fins handed their patterns."""
        messages = [m for m in self.decoder.feed(data) if keep()]
        self.firmware.crc_errors = self.decoder.crc_errors + self.decoder.checksum_errors
        replies = [self.firmware.receive(m, now) for m in messages]
        apply_firmware(self.firmware, model)
        return [to_pc(pr.encode_message(r)) for r in replies if r is not None], messages

    def advance(self, model: FishModel, target: float, trace: list | None) -> list[bytes]:
        """See :meth:`RobotFirmware.advance`: a tick before every :data:`CHUNK` of the model."""
        frames: list[bytes] = []
        while model.time < target:
            self.firmware.tick(model.time, model.fin_angles()[0][0])
            apply_firmware(self.firmware, model)
            kinds = stroke_kinds(model)
            model.advance(min(CHUNK, target - model.time))
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


def make_firmware(impl: str, config: FirmwareConfig | None, boot: int, variant: str | None = None) -> RobotFirmware:
    """The rules an emulated robot runs: ``impl`` ``"python"`` (reference) or ``"c"`` (``variant``: a broken build)."""
    if impl == "python":
        if variant is not None:
            raise ValueError("a firmware variant needs the C firmware (firmware_impl='c')")
        return PythonFirmware(config, boot)
    if impl == "c":
        from pectoral_gym.hardware.emulated_cfirmware import CFirmware

        return CFirmware(config, boot, variant=variant)
    raise ValueError(f"firmware_impl must be one of {', '.join(FIRMWARES)}, got {impl!r}")
