"""The robot's fin rules: what the fins latch of a command, and when (the firmware's rules, on the PC too).

The fins run only patterns the firmware hands them, by these rules (``docs/protocol.md`` section 5,
``docs/hardware.md``, "The firmware's rate rule"):

* **Clip** every command to the servo limits (:func:`~pectoral_gym.model.servo.clip_beats`, with the peak-rate
  stretch of the period; :mod:`pectoral_gym.model.servo`, the servo limits' one home).
* **Latch at the next turning point**: a fin takes a new pattern where its half-stroke in progress ends (the
  parameter-change rule of ``docs/model.md`` section 5); a still fin latches at once.
* **The rate rule at the latch**: a moving fin's pattern moves towards the command by at most ``max_rate`` times
  the half-stroke that ends (:func:`slew_at_latch`).
* **The transitional stretch**: the half-stroke from the turning point is slowed to the servos' peak rate
  (:func:`stretch_transition`). :func:`next_latch` is the two together, batched for any number of fish.
* **The tick**: the firmware decides every :data:`CHUNK` of robot time; it hands a pattern over when a command
  arrives or what the fins are to run changes (:func:`apply_firmware`), halts them where they are, and the model
  advances between ticks (:func:`advance_with_firmware`).

:class:`FinState` is the fins' side of the firmware (the clipped command, the setpoint, a pending halt, what was
handed over last); the robot's session, lease and sequence rules drive it on the robot
(:class:`pectoral_gym.hardware.radio.firmware.Firmware`), the PC's replay of the commands it sent on the PC
(:class:`pectoral_gym.model.finreplay.FinReplay`). Patterns reach the robot at the radio's resolution
(:func:`wire_beats`). :func:`force_latch` starts a half-stroke a robot reported, :func:`latched` finds the latches
of a model's fins.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from pectoral_gym.model import strokes
from pectoral_gym.model.models import FishModel
from pectoral_gym.model.params import FinBeat
from pectoral_gym.model.servo import ServoLimits, _patterns, clip_beats, rest_beats

__all__ = ["CHUNK", "FIN_WIRE_SCALE", "FinState", "FirmwareConfig", "advance_with_firmware", "apply_firmware",
           "fin_words", "force_latch", "latched", "next_latch", "rate_limit", "slew_at_latch", "stretch_transition",
           "stroke_kinds", "wire_beats"]

CHUNK = 0.01  # the firmware's tick: the fin model's step between two of its decisions [robot s]

#: A pattern on the radio, per fin (bias, amplitude, period, ratio): ``value * scale`` rounded to a u16
#: (mrad, mrad, ms, 1/1000); the robot runs what arrives.
FIN_WIRE_SCALE = (1000.0, 1000.0, 1000.0, 1000.0)


def fin_words(values: Sequence[float]) -> list[int]:
    """The wire's u16 words of 8 pattern values (right fin, then left; SI units).

    Raises:
        ValueError: If there are not 8 values, or one does not fit (not finite, or outside 0..65.535).
    """
    values = [float(v) for v in values]
    if len(values) != 8:
        raise ValueError(f"SET_FINS needs 8 values (right fin then left fin), got {len(values)}")
    words = []
    for i, v in enumerate(values):
        if not math.isfinite(v):
            raise ValueError(f"SET_FINS value {i} is not finite: {v!r}")
        w = round(v * FIN_WIRE_SCALE[i % 4])
        if not 0 <= w <= 0xFFFF:
            raise ValueError(f"SET_FINS value {i} = {v!r} does not fit the wire format (0..65.535 in SI units)")
        words.append(w)
    return words


def wire_beats(beats: np.ndarray) -> np.ndarray:
    """``(2, 4)`` patterns as the robot receives them (quantised by :func:`fin_words`; same errors)."""
    words = fin_words(np.asarray(beats, dtype=float).reshape(8))
    return np.array([w / FIN_WIRE_SCALE[i % 4] for i, w in enumerate(words)]).reshape(2, 4)


@dataclass(frozen=True)
class FirmwareConfig:
    """Settings of the robot-side rules (the firmware's; a run log's header records them).

    Attributes:
        watchdog_timeout: Halt the fins after this long without a new valid message [s]; at most 1 s.
        max_lease: Longest lease the robot grants a command, whatever the message asks [s]; at most 1 s.
        limits: Servo limits for clipping and rate limiting.
    """

    watchdog_timeout: float = 0.5
    max_lease: float = 1.0
    limits: ServoLimits = field(default_factory=ServoLimits)

    def __post_init__(self) -> None:
        if not 0 < self.watchdog_timeout <= 1.0:
            raise ValueError(f"watchdog_timeout must be in (0, 1] s, got {self.watchdog_timeout!r}")
        if not 0 < self.max_lease <= 1.0:
            raise ValueError(f"max_lease must be in (0, 1] s, got {self.max_lease!r}")


def stretch_transition(beats: np.ndarray, turn: np.ndarray, next_power: np.ndarray,
                       limits: ServoLimits) -> np.ndarray:
    """Lengthen the period of ``(2, 4)`` patterns so the transitional half-stroke stays within ``max_speed``.

    A fin latches a new pattern at a turning point ``turn`` [rad] and then swings to ``bias + A`` in
    ``T_p / (zeta + 1)`` (``next_power``) or to ``bias - A`` in ``zeta T_p / (zeta + 1)``
    (``docs/model.md``, "Changing fin parameters"); its peak rate is ``pi |to - turn| / (2 d)``
    (:func:`pectoral_gym.model.dynamics.stroke_kinematics`). Input: patterns already clipped by :func:`clip_beats`;
    a batch ``(..., 2, 4)`` with ``turn`` and ``next_power`` ``(..., 2)`` is stretched pattern by pattern.
    """
    out = _patterns(beats)
    turn, power = np.asarray(turn, dtype=float), np.asarray(next_power, dtype=bool)
    to = np.where(power, out[..., 0] + out[..., 1], out[..., 0] - out[..., 1])
    share = np.where(power, 1.0, out[..., 3]) / (out[..., 3] + 1.0)  # d = share * T_p
    need = math.pi * np.abs(to - turn) / (2.0 * limits.max_speed * share)
    out[..., 2] = np.minimum(np.maximum(out[..., 2], need), limits.period_max)
    return out


def slew_at_latch(beats: np.ndarray, latched: np.ndarray, duration: np.ndarray, still: np.ndarray,
                  limits: ServoLimits) -> np.ndarray:
    """The patterns fins latch at their next turning point for the command ``beats`` (the firmware's rate rule).

    A moving fin latches ``beats`` moved from the pattern it runs, ``latched``, by at most ``max_rate`` times
    ``duration`` [s], the half-stroke that the turning point ends; a ``still`` fin latches ``beats``. The result
    is clipped (:func:`clip_beats`: a pattern part-way may need a longer period for ``max_speed``).

    Args:
        beats: ``(..., 2, 4)`` commanded patterns, clipped by :func:`clip_beats`.
        latched: ``(..., 2, 4)`` the patterns the fins run (bias, amplitude, period, ratio).
        duration: ``(..., 2)`` duration of each fin's half-stroke in progress [s].
        still: ``(..., 2)`` whether each fin is at rest (its half-stroke ends where it starts).
        limits: The servo limits (``max_rate``).
    """
    b = _patterns(beats)
    step = np.asarray(limits.max_rate, dtype=float) * np.maximum(np.asarray(duration, dtype=float), 0.0)[..., None]
    ran = np.asarray(latched, dtype=float)
    # Within reach the command itself, bit for bit: ran + (b - ran) may differ from b in the last bit, and a fin
    # whose half-stroke then ends 1e-16 rad from where it starts counts as moving and misses its latch at once.
    moved = np.where(np.abs(b - ran) <= step, b, ran + np.clip(b - ran, -step, step))
    return clip_beats(np.where(np.asarray(still, dtype=bool)[..., None], b, moved), limits)[0]


def rate_limit(current: np.ndarray, target: np.ndarray, dt: float, limits: ServoLimits) -> np.ndarray:
    """Move ``current`` towards ``target`` by at most ``max_rate * dt`` per parameter (both ``(2, 4)``)."""
    step = np.asarray(limits.max_rate, dtype=float) * max(float(dt), 0.0)
    return np.asarray(current, float) + np.clip(np.asarray(target, float) - current, -step, step)


class FinState:
    """The fins' side of the robot's firmware, which :func:`apply_firmware` hands to a model's fins.

    A subclass supplies the state machine: :attr:`running` and :meth:`tick` (the robot's sessions, leases and
    watchdog, :class:`pectoral_gym.hardware.radio.firmware.Firmware`; the PC's replay of its own commands).

    Args:
        config: The rules' settings (:class:`FirmwareConfig`; default: the robot's).

    Attributes:
        config: The rules' settings.
        command: ``(2, 4)`` the last accepted command, clipped to the servo limits (:meth:`accept`).
        clipped: Whether clipping changed it.
        setpoint: ``(2, 4)`` the pattern the fins should run (valid while running): the command, or rest where
            halted fins hold still (:meth:`update_setpoint`); what a turning point latches of it is
            :func:`next_latch`'s.
        halt: Set when the fins must stop at once; :func:`apply_firmware` halts them and clears it.
        command_id: Identity of the last command (``None`` before the first).
        handed: ``(2, 4)`` the pattern last handed to the fins and ``handed_id`` the command it came from
            (``None``: nothing handed since power-up or a halt; :func:`apply_firmware`).
        latch_memo: What :func:`next_latch` read at the last tick that ran it, as bits, with the limits and the
            ``handed`` it gave (``None``: none kept); :func:`apply_firmware` skips the rules while it holds.
    """

    def __init__(self, config: FirmwareConfig | None = None):
        self.config = config or FirmwareConfig()
        self.command = rest_beats()
        self.setpoint = rest_beats()
        self.halt = False
        self.clipped = False
        self.command_id: int | None = None
        self.handed: np.ndarray | None = None
        self.handed_id: int | None = None
        self.latch_memo: tuple | None = None

    @property
    def running(self) -> bool:
        """Whether the fins are beating (the subclass's state machine says)."""
        raise NotImplementedError

    def tick(self, now: float, fin_angles: np.ndarray | None = None) -> None:
        """Advance the rules to ``now`` [s], given the fins' angles ``(2,)`` [rad] (the subclass's)."""
        raise NotImplementedError

    def accept(self, fins: np.ndarray) -> None:
        """A new command ``fins`` (8 values, or ``(2, 4)``; rad, rad, s, -): clipped to the servo limits."""
        self.command, self.clipped = clip_beats(np.asarray(fins, dtype=float).reshape(2, 4), self.config.limits)

    def update_setpoint(self, fin_angles: np.ndarray | None = None) -> None:
        """The setpoint at a tick: the command while running, else rest at ``fin_angles`` ``(2,)`` [rad] if given."""
        if self.running:
            self.setpoint = self.command.copy()  # rate-limited where the fins latch it (next_latch)
        elif fin_angles is not None:
            self.setpoint = rest_beats(fin_angles)


def apply_firmware(firmware: FinState, model: FishModel) -> None:
    """Hand the firmware's decision to fish 0 of ``model``: halt the fins where they are, or command the setpoint.

    A running command is handed over when it arrives or what the fins are to run changes (not again at every
    tick), latched at the next turning point, rate-limited there (:func:`slew_at_latch`); its transitional
    half-stroke from there is bounded by :func:`stretch_transition`.

    :func:`next_latch` is a function of the setpoint, the limits and the fields ``DURATION`` to ``RATIO`` of the
    half-strokes in progress alone, and those change only at a command, a turning point, a halt or a reported
    latch, not at most ticks. A tick whose inputs are those of the last tick that ran it, bit for bit
    (``firmware.latch_memo``), and whose fins still hold what that tick handed them, would hand nothing over:
    it returns at once. Whatever changed an input (a tick, :func:`force_latch`, a restored checkpoint), the
    bits differ and the rules run.
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
        limits = firmware.config.limits
        # All that next_latch reads of the fins: the fields DURATION..RATIO (adjacent), as bits.
        inputs = (firmware.setpoint.tobytes(), model.fins[0, :, strokes.DURATION:strokes.RATIO + 1].tobytes())
        memo = firmware.latch_memo
        if memo is not None and memo[0] == inputs and memo[1] is limits and memo[2] is firmware.handed \
                and firmware.command_id == firmware.handed_id:
            return  # next_latch would give what the fins were handed: _hand_over would change nothing
        _hand_over(firmware, model, safe := next_latch(firmware.setpoint, model.fins[0], limits))
        handed = firmware.handed
        # kept only where _hand_over would skip the same result again (not for a nan, which never equals itself)
        firmware.latch_memo = (inputs, limits, handed) if handed is not None and bool((handed == safe).all()) \
            else None


def next_latch(beats: np.ndarray, fins: np.ndarray, limits: ServoLimits) -> np.ndarray:
    """What fins latch at their next turning point for the command ``beats`` ``(..., 2, 4)`` (the firmware's rules).

    The rate rule from the pattern each fin runs (:func:`slew_at_latch`), then the transitional half-stroke from
    the fin's next turning point bounded by the servos' peak rate (:func:`stretch_transition`).
    ``fins`` ``(..., 2, FIN_FIELDS)`` are the half-strokes in progress (:mod:`pectoral_gym.model.strokes`); a fin
    whose half-stroke ends where it starts is still (it latches at once, and its next half-stroke is a power
    stroke).
    """
    still = fins[..., strokes.ANGLE_FROM] == fins[..., strokes.ANGLE_TO]
    next_power = still | (fins[..., strokes.POWER] < 0.5)
    latched = slew_at_latch(beats, fins[..., strokes.BIAS:strokes.RATIO + 1], fins[..., strokes.DURATION], still,
                            limits)
    return stretch_transition(latched, fins[..., strokes.ANGLE_TO], next_power, limits)


def _hand_over(firmware: FinState, model: FishModel, safe: np.ndarray) -> None:
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


def advance_with_firmware(firmware: FinState, model: FishModel, target: float,
                          after_chunk: Callable[[], None] | None = None) -> None:
    """Advance ``model`` (fish 0) to time ``target`` [s] in :data:`CHUNK` steps, ticking the firmware before each."""
    while model.time < target:
        firmware.tick(model.time, model.fin_angles()[0][0])
        apply_firmware(firmware, model)
        model.advance(min(CHUNK, target - model.time))
        if after_chunk is not None:
            after_chunk()
