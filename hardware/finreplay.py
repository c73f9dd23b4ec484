"""The robot's fins replayed on the PC: the stroke phase a fin-observing policy needs, which the robot does not report.

The robot's STATUS message carries no fin angles, but its fins move by known rules: the firmware
(:class:`pectoral_gym.hardware.radio.firmware.Firmware`: leases, rate limiting, halts) hands its setpoint to fins that
follow the parameter-change rule of ``docs/model.md`` section 5, the transitional half-stroke
bounded by :func:`pectoral_gym.hardware.radio.firmware.stretch_transition`. :class:`FinReplay` runs those same rules on
the PC, fed the commands the PC sends (as they go on the wire, quantised) at the times it sends them,
so :class:`pectoral_gym.hardware.env.HardwareFishEnv` can give the observation's fin block
(``observe_fins=True``, :mod:`pectoral_gym.envs.observation`). The emulator drives its own fins with
the same two functions, :func:`apply_firmware` and :func:`advance_with_firmware`.

What the replay cannot see: the radio latency (the robot latches a command a few milliseconds after
the PC sent it) and the firmware's tick (10 ms); a latch may therefore fall one tick apart, and
after a safety stop the fins are taken as halted when the PC learns of it. The fins' angles at
power-up are taken as 90 deg (the firmware's rest). A robot that reports its latches (LATCH messages,
``docs/protocol.md``) removes the first: :meth:`FinReplay.latch` starts the reported half-stroke where and
when the robot says it started (:func:`force_latch`), and the rules infer only what lies between reports
(a lost report, a robot that does not send them). The calibration's replay of a run log uses it; the live
env's fin block does not (it keeps the commands' timing, as the simulated envs a policy trains in:
``docs/hardware.md``). :func:`latched` finds the latches of a model's fins, for the emulator's reports.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from pectoral_gym.hardware.radio import protocol as pr
from pectoral_gym.hardware.radio.firmware import (
    Firmware,
    FirmwareConfig,
    ServoLimits,
    slew_at_latch,
    stretch_transition,
)
from pectoral_gym.model import strokes
from pectoral_gym.model.models import FishModel
from pectoral_gym.model.params import FinBeat, FishParams
from pectoral_gym.model.spec import FULL_REFERENCE

__all__ = ["CHUNK", "FinReplay", "advance_with_firmware", "apply_firmware", "force_latch", "latched", "next_latch",
           "stroke_kinds"]

CHUNK = 0.01  # fin-model step between firmware ticks [robot s]


def apply_firmware(firmware: Firmware, model: FishModel) -> None:
    """Hand the firmware's decision to fish 0 of ``model``: halt the fins where they are, or command the setpoint.

    A running command is handed over when it arrives or what the fins are to run changes (not again at every
    tick), latched at the next turning point, rate-limited there
    (:func:`~pectoral_gym.hardware.radio.firmware.slew_at_latch`); its transitional half-stroke from there is
    bounded by :func:`~pectoral_gym.hardware.radio.firmware.stretch_transition`.
    """
    if firmware.halt:
        angles = model.fin_angles()[0][0]
        time_now = model.time
        model.reset(model.state.copy(), right=FinBeat.rest(float(angles[0])), left=FinBeat.rest(float(angles[1])),
                    index=np.arange(1))
        model.time = time_now
        firmware.halt = False
        firmware.handed = None  # a restart hands the fins their patterns
    elif firmware.running:
        _hand_over(firmware, model, next_latch(firmware.setpoint, model.fins[0], firmware.config.limits))


def next_latch(beats: np.ndarray, fins: np.ndarray, limits: ServoLimits) -> np.ndarray:
    """What fins latch at their next turning point for the command ``beats`` ``(..., 2, 4)`` (the firmware's rules).

    The rate rule from the pattern each fin runs (:func:`~pectoral_gym.hardware.radio.firmware.slew_at_latch`),
    then the transitional half-stroke from the fin's next turning point bounded by the servos' peak rate
    (:func:`~pectoral_gym.hardware.radio.firmware.stretch_transition`). ``fins`` ``(..., 2, FIN_FIELDS)`` are the
    half-strokes in progress (:mod:`pectoral_gym.model.strokes`); a fin whose half-stroke ends where it starts is
    still (it latches at once, and its next half-stroke is a power stroke).
    """
    still = fins[..., strokes.ANGLE_FROM] == fins[..., strokes.ANGLE_TO]
    next_power = still | (fins[..., strokes.POWER] < 0.5)
    latched = slew_at_latch(beats, fins[..., strokes.BIAS:strokes.RATIO + 1], fins[..., strokes.DURATION], still,
                            limits)
    return stretch_transition(latched, fins[..., strokes.ANGLE_TO], next_power, limits)


def _hand_over(firmware: Firmware, model: FishModel, safe: np.ndarray) -> None:
    """Hand patterns ``safe`` ``(2, 4)`` to fish 0: both fins on a new command, else each fin whose pattern changed.

    As the simulated envs command the fins once per control period: handing an unchanged pattern over at every
    tick would restart a still fin's half-stroke (``strokes.command_one``: a fin not moving latches at once) at
    every tick, a phase (the fin block's time left) the simulation never shows. A fin handed its own pattern
    again is otherwise untouched, so keeping its phase is all that handing over per fin changes.
    """
    if firmware.command_id != firmware.handed_id or firmware.handed is None:
        changed = np.ones(2, dtype=bool)
    else:
        changed = np.any(safe != firmware.handed, axis=1)
    if not changed.any():
        return
    fins = model.fins[0]
    kept = fins[:, [strokes.ELAPSED, strokes.POWER]].copy()
    model.command_array(safe.reshape(1, 2, 4))
    for f in np.flatnonzero(~changed):
        fins[f, strokes.ELAPSED], fins[f, strokes.POWER] = kept[f]
    firmware.handed, firmware.handed_id = safe, firmware.command_id


def stroke_kinds(model: FishModel) -> np.ndarray:
    """``(2,)`` kinds of fish 0's half-strokes in progress (1 power, 0 recovery), for :func:`latched`."""
    return model.fins[0, :, strokes.POWER].copy()


def latched(model: FishModel, kinds_before: np.ndarray) -> list[tuple[int, float]]:
    """Fins of fish 0 that latched since ``kinds_before`` (:func:`stroke_kinds`) was read: ``(fin, time)``.

    Every latch flips the stroke's kind, and a half-stroke lasts far longer than one firmware tick (at least
    ``period_min / (ratio_max + 1)``, 57 ms at the default limits), so an advance of one tick holds at most one
    latch per fin: a flipped kind is a latch, which happened ``ELAPSED`` before the model's time.
    """
    fins = model.fins[0]
    return [(f, float(model.time - fins[f, strokes.ELAPSED])) for f in range(2)
            if fins[f, strokes.POWER] != kinds_before[f]]


def force_latch(model: FishModel, fin: int, t: float, beat: np.ndarray, turn: float, power: bool) -> None:
    """Every fish of ``model``: fin ``fin`` latched ``beat`` at time ``t`` [s] at angle ``turn`` [rad] (a report).

    The half-stroke that started there replaces the one in progress (``docs/model.md`` section 5: from
    ``turn`` to ``bias + amplitude`` in ``period / (ratio + 1)`` for a power stroke, to ``bias - amplitude``
    in ``ratio period / (ratio + 1)`` for a recovery), ``model.time - t`` into it; the commanded pattern
    (``pending``) is left as it is, for the next turning point.
    """
    bias, amp, period, ratio = (float(v) for v in np.asarray(beat, dtype=float).reshape(4))
    fins = model.fins
    fins[:, fin, strokes.ANGLE_FROM] = float(turn)
    fins[:, fin, strokes.ANGLE_TO] = bias + amp if power else bias - amp
    fins[:, fin, strokes.DURATION] = (1.0 if power else ratio) * period / (ratio + 1.0)  # eq. (21)
    fins[:, fin, strokes.ELAPSED] = max(model.time - float(t), 0.0)
    fins[:, fin, strokes.POWER] = 1.0 if power else 0.0
    fins[:, fin, strokes.BIAS:strokes.RATIO + 1] = (bias, amp, period, ratio)


def advance_with_firmware(firmware: Firmware, model: FishModel, target: float,
                          after_chunk: Callable[[], None] | None = None) -> None:
    """Advance ``model`` (fish 0) to time ``target`` [s] in :data:`CHUNK` steps, ticking the firmware before each."""
    while model.time < target:
        firmware.tick(model.time, model.fin_angles()[0][0])
        apply_firmware(firmware, model)
        model.advance(min(CHUNK, target - model.time))
        if after_chunk is not None:
            after_chunk()


class FinReplay:
    """The robot's fins, replayed from the commands the PC sends.

    Times are the PC's experiment clock [robot s] (``HardwareFishEnv.now()``).

    Args:
        params: Model parameters (only the fin kinematics matter).
        firmware: The robot's firmware settings (servo limits, lease).
    """

    _SESSION = 1

    def __init__(self, params: FishParams | None = None, firmware: FirmwareConfig | None = None):
        self.firmware_config = firmware
        self.model = FULL_REFERENCE.build(1, params)  # the fins' kinematics: the integration preset does not matter
        self.reset(0.0)

    def reset(self, t: float) -> None:
        """Fins at rest at 90 deg at time ``t`` (power-up, or a new replay)."""
        self.firmware = Firmware(self.firmware_config)
        self.model.reset()
        self.model.time = float(t)
        self._seq = self._command = 0

    def _message(self, msg: pr.Message) -> None:
        # Through the wire format: the robot runs the quantised command.
        self.firmware.receive(pr.decode_message(pr.encode_message(msg)), self.model.time)

    def _next_seq(self) -> int:
        self._seq = (self._seq + 1) & 0xFFFF
        return self._seq

    def command(self, t: float, beats: np.ndarray) -> None:
        """The PC sent a new command ``beats`` ``(2, 4)`` at time ``t``.

        The replay keeps it running until :meth:`stop` or the next command: the PC's keep-alives and
        lease renewals keep the robot running, and when a lease or the watchdog stops the robot the
        PC's supervisor stops the episode, which calls :meth:`stop`.
        """
        self.advance(t)
        self._command = (self._command + 1) & 0xFFFF
        fins = tuple(float(v) for v in np.asarray(beats, dtype=float).reshape(8))
        self._message(pr.Message(pr.MsgType.SET_FINS, self._next_seq(), self._SESSION, fins=fins,
                                 command=self._command, lease=self.firmware.config.max_lease))
        self.firmware.lease_end = math.inf
        self.firmware.last_valid = math.inf  # no watchdog in the replay (see above)

    def stop(self, t: float) -> None:
        """The fins were stopped at time ``t`` (STOP, a safety trip): they halt where they are."""
        self.advance(t)
        self._message(pr.Message(pr.MsgType.STOP, self._next_seq(), self._SESSION))
        apply_firmware(self.firmware, self.model)  # the halt, now

    def latch(self, t: float, fin: int, beat: np.ndarray, turn: float, power: bool) -> bool:
        """The robot reported that fin ``fin`` latched ``beat`` at angle ``turn`` at time ``t`` (a LATCH).

        The replay runs to ``t`` and starts that half-stroke (:func:`force_latch`); a report that comes
        after the replay passed ``t`` starts it as far in as the replay is. What the firmware commands next
        is inferred as before. Ignored while the replayed fins are halted (a report from just before the
        robot heard a stop, mapped after it: the fins are still now). Returns whether the report was applied.
        """
        self.advance(t)
        if not self.firmware.running:
            return False
        force_latch(self.model, fin, t, beat, turn, power)
        return True

    def advance(self, t: float) -> None:
        """Run the fins to time ``t`` (earlier times are ignored)."""
        advance_with_firmware(self.firmware, self.model, float(t))

    @property
    def fins(self) -> np.ndarray:
        """``(1, 2, strokes.FIN_FIELDS)`` the replayed half-strokes in progress (:mod:`pectoral_gym.model.strokes`)."""
        return self.model.fins
