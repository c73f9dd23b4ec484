"""The robot-side rules as a pure state machine (what the dsPIC firmware must do; ``docs/protocol.md``).

:class:`Firmware` knows nothing of sockets, clocks or physics: the caller hands it decoded messages
and the time, and reads back the fin setpoint, whether the fins must halt, and the STATUS replies.
The emulator drives a :class:`~pectoral_gym.model.models.FullModel` with it; the same rules are the
specification of the real firmware. The fin itself latches a new setpoint at its next stroke turning
point (the parameter-change rule of the core models, reused by the emulator through
``FullModel.command``); a halt is immediate (the servos hold their current angle).

Rules:

* **Lease and deadline** (protocol version 3): a SET_FINS runs until its lease, counted from the receipt
  of the *first* copy of its command identity, or its ``deadline`` on the robot's own clock (uptime in
  ms, for the robot's current boot id), whichever is first. A deadline already past, or one for another
  boot, never starts the fins. Copies (same identity: keep-alives, retries, replays) never extend it and
  never restart stopped fins; only a newer identity from the controller's ``step()`` does. At expiry ->
  state ``EXPIRED``, fins halt.
* **Session**: the robot serves one session at a time. Another session takes over only when the served
  one has been silent for ``watchdog_timeout`` (it is gone) or with a CLAIM (an operator's explicit
  takeover): running fins halt and the old session is retired (never served again). Otherwise its
  messages are refused, but answered: every STATUS names the session it answers and the one served.
* **STOP** from any session (served, retired or unknown) -> state ``STOPPED``, fins halt at once: a stop
  never needs authority. From the served session a stale STOP is still ignored (ordering).
* **Watchdog**: no new, valid message of the current session for ``watchdog_timeout`` (default 0.5 s) ->
  state ``WATCHDOG``, fins halt. Duplicates, stale, foreign and retired messages never feed it.
* **Boot id**: random, nonzero, new at every power-up; reported in every STATUS with the uptime.
* **Clipping** to :class:`ServoLimits`: stroke ``bias +- amplitude`` inside the servo's angle range,
  period and ratio inside theirs, and the *peak* fin rate of both half-strokes at most ``max_speed``
  (the period is lengthened, :func:`clip_beats`); the transitional half-stroke from the fin's next
  turning point is bounded the same way (:func:`stretch_transition`, applied where the fin latches).
* **Rate limiting, per latch**: the pattern a moving fin latches at a turning point differs from the one it
  ran by at most ``max_rate`` per parameter times that half-stroke's duration (:func:`slew_at_latch`); a
  still fin latches the command, its first half-stroke from rest bounded by ``max_speed`` (above). The fins
  only ever run latched patterns, so a moving fin's pattern changes at most ``max_rate`` per second, as a
  per-tick slew of the setpoint bounds it; but what a turning point latches does not depend on the
  milliseconds between a command's arrival and the firmware's tick, so the PC's replay knows it
  (``docs/hardware.md``, "The firmware's rate rule").
* **Sequence numbers**: new -> act and acknowledge; duplicate -> acknowledge only (a retry whose first
  copy arrived); stale -> ignore. All counted.
* **The robot's clock**: the rules' times (uptime, lease end, deadline, watchdog) are whole milliseconds, as on the
  robot's u32 millisecond clock: the caller's float seconds are read as the millisecond they fall in, a time within
  :data:`MS_GUARD` ms below a whole ms counting as that ms (``k / 1000.0`` is often a hair below ``k`` ms in
  float64, and the robot's float32 turning points are known to ~1e-4 ms), and the comparisons are between integers.
  Float sums such as ``now + lease`` against a tick's float time tie-broke 1 ms differently from the robot; the
  C firmware (``firmware/``) is held to this reference stream by stream (``tests/test_firmware_differential.py``).
* **Latch reports**: while running, every time a fin latches a pattern that moves it (not a half-stroke that
  ends where it starts) at a stroke turning point, the robot sends a LATCH to the served session
  (:meth:`Firmware.latch_report`; fire and forget, numbered on their own): the uptime then, the fin, the
  pattern as the fin runs it, the turning-point angle and the stroke's kind. They change nothing on the robot.
  Messages of the robot's own types (STATUS, LATCH) are ignored.
"""

from __future__ import annotations

import math
import secrets
from dataclasses import dataclass, field

import numpy as np

from pectoral_gym.hardware.radio.protocol import (
    Latch,
    Message,
    MsgType,
    RobotState,
    SequenceTracker,
    Status,
    StatusFlag,
    Verdict,
    serial_newer,
)
from pectoral_gym.model.servo import ROBOT_MAX_FIN_RATE, servo_period

__all__ = ["MS_GUARD", "ServoLimits", "FirmwareConfig", "Firmware", "clip_beats", "rate_limit", "rest_beats",
           "peak_rates", "slew_at_latch", "stretch_transition", "new_boot_id"]

_RETIRED = 16  # sessions remembered as retired (a restarted PC gets a fresh random 32-bit session)
#: A time within this many ms below a whole millisecond counts as that millisecond (1 us: above float64's rounding
#: of a time and the robot's float32 turning points, far below anything a millisecond clock resolves).
MS_GUARD = 1e-3


def new_boot_id(rng=None) -> int:
    """A random nonzero 32-bit boot id (from ``rng``, a numpy ``Generator``, if given; else the OS's source)."""
    boot = int(rng.integers(0, 2**32)) if rng is not None else secrets.randbits(32)
    return boot or 1


def _default_rate() -> tuple[float, float, float, float]:
    return (math.radians(180.0), math.radians(180.0), 4.0, 10.0)


@dataclass(frozen=True)
class ServoLimits:
    """What the fin servos can do; commands are clipped to these (PC side and robot side alike).

    The defaults admit the simulated environments' default action ranges except their fastest strokes:
    a power stroke peaks at ``pi A (zeta + 1) / T_p`` (eq. 21), above ``max_speed`` for large amplitudes
    at short periods and high ratios, e.g. 19.7 rad/s for (90 deg, 30 deg, 0.5 s, 5), which
    :func:`clip_beats` slows to a 0.76 s period.

    Attributes:
        angle_min: Smallest fin angle [rad] (stroke ``bias - amplitude``).
        angle_max: Largest fin angle [rad] (stroke ``bias + amplitude``).
        period_min: Shortest fin-beat period [s].
        period_max: Longest fin-beat period [s].
        ratio_min: Smallest power/recovery speed ratio [-].
        ratio_max: Largest ratio [-].
        max_speed: Fastest fin angular rate [rad/s]: the peak ``|g'|`` of every half-stroke, eq. (21).
        max_rate: Largest change per second of (bias [rad/s], amplitude [rad/s], period [s/s], ratio [1/s]).
    """

    angle_min: float = math.radians(10.0)
    angle_max: float = math.radians(170.0)
    period_min: float = 0.4
    period_max: float = 4.0
    ratio_min: float = 0.5
    ratio_max: float = 6.0
    max_speed: float = ROBOT_MAX_FIN_RATE
    max_rate: tuple[float, float, float, float] = field(default_factory=_default_rate)

    def __post_init__(self) -> None:
        values = (self.angle_min, self.angle_max, self.period_min, self.period_max, self.ratio_min,
                  self.ratio_max, self.max_speed, *self.max_rate)
        if len(self.max_rate) != 4 or not all(math.isfinite(v) for v in values):
            raise ValueError("ServoLimits: all limits must be finite and max_rate must have 4 entries")
        if not 0 <= self.angle_min < self.angle_max <= math.pi:
            raise ValueError(f"ServoLimits: need 0 <= angle_min < angle_max <= pi, got {self.angle_min}, "
                             f"{self.angle_max}")
        if not 0 < self.period_min <= self.period_max or not 0 < self.ratio_min <= self.ratio_max:
            raise ValueError("ServoLimits: need 0 < period_min <= period_max and 0 < ratio_min <= ratio_max")
        if self.max_speed <= 0 or min(self.max_rate) <= 0:
            raise ValueError("ServoLimits: max_speed and max_rate must be > 0")
        # The slowest stroke must be slow enough for the widest swing (stretching always succeeds).
        span = self.angle_max - self.angle_min
        worst = math.pi * span * (self.ratio_min + 1.0) / (2.0 * self.period_max * self.ratio_min)
        worst = max(worst, math.pi * span * (self.ratio_max + 1.0) / (2.0 * self.period_max))
        if worst > self.max_speed:
            raise ValueError(f"ServoLimits: a full swing at period_max peaks at {worst:.2f} rad/s > max_speed; "
                             "raise period_max or narrow the angle or ratio range")


def rest_beats(angles: np.ndarray | None = None) -> np.ndarray:
    """``(2, 4)`` fins held still at ``angles`` (default 90 deg): amplitude 0, period 1 s, ratio 1."""
    angles = np.full(2, math.pi / 2) if angles is None else np.asarray(angles, dtype=float)
    return np.stack([np.array([a, 0.0, 1.0, 1.0]) for a in angles])


def clip_beats(beats: np.ndarray, limits: ServoLimits) -> tuple[np.ndarray, bool]:
    """Clip ``(2, 4)`` fin patterns to ``limits``; returns ``(clipped, changed)``. Input must be finite.

    A batch ``(..., 2, 4)`` is clipped pattern by pattern (``changed``: any of them), as the backup shield's
    rollouts do (:mod:`pectoral_gym.agents.controllers.firmware_path`); 8 values are read as ``(2, 4)``.
    """
    b = _patterns(beats)
    out = b.copy()
    half_range = 0.5 * (limits.angle_max - limits.angle_min)
    out[..., 1] = np.clip(out[..., 1], 0.0, half_range)
    out[..., 0] = np.clip(out[..., 0], limits.angle_min + out[..., 1], limits.angle_max - out[..., 1])
    out[..., 2] = np.clip(out[..., 2], limits.period_min, limits.period_max)
    out[..., 3] = np.clip(out[..., 3], limits.ratio_min, limits.ratio_max)
    # Peak rate of the faster half-stroke, eq. (21): pi A (zeta + 1) / (T_p min(1, zeta)); slow the period.
    out[..., 2] = servo_period(out[..., 1], out[..., 2], out[..., 3], limits.max_speed)  # <= period_max (ServoLimits)
    return out, bool(np.any(np.abs(out - b) > 1e-12))


def _patterns(beats: np.ndarray) -> np.ndarray:
    """A float copy of ``beats`` as ``(..., 2, 4)`` patterns (8 values as one ``(2, 4)``)."""
    b = np.array(beats, dtype=float)
    return b if b.shape[-2:] == (2, 4) else b.reshape(2, 4)


def peak_rates(beats: np.ndarray) -> np.ndarray:
    """``(2, 2)`` peak ``|g'|`` [rad/s] of the power and recovery half-strokes of ``(2, 4)`` patterns.

    Each half of eq. (21) is a half-cosine: swing ``2 A`` in ``T_p / (zeta + 1)`` (power) or
    ``zeta T_p / (zeta + 1)`` (recovery); the peak of ``half * pi / d * sin`` is ``pi * swing / (2 d)``.
    """
    b = np.asarray(beats, dtype=float).reshape(2, 4)
    a, period, ratio = b[:, 1], b[:, 2], b[:, 3]
    power = math.pi * a * (ratio + 1.0) / period
    return np.stack([power, power / ratio], axis=1)


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


@dataclass(frozen=True)
class FirmwareConfig:
    """Settings of the robot-side rules.

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


class Firmware:
    """The robot's rules, driven by :meth:`receive` (messages) and :meth:`tick` (time).

    Args:
        config: The rules' settings.
        boot: This power-up's boot id (nonzero; default: a fresh random one, :func:`new_boot_id`).
        power_up: The caller's clock at power-up [s]: the uptime reported in STATUS counts from it.

    Attributes:
        state: A :class:`RobotState`.
        command: ``(2, 4)`` the last accepted SET_FINS, clipped to the servo limits.
        setpoint: ``(2, 4)`` the pattern the fins should run (valid while running): the command, or rest where
            halted fins hold still; what a turning point latches of it is :func:`slew_at_latch`'s.
        halt: Set when the fins must stop at once; the caller clears it after halting them.
        tracker: Sequence bookkeeping of the current session's messages.
        session: The session served (``None`` before the first message).
        command_id: Identity of the last command run (``None`` before the first).
        handed: ``(2, 4)`` the pattern last handed to the fins and ``handed_id`` the command it came from
            (``None``: nothing handed since power-up or a halt; ``finreplay.apply_firmware``).
        lease_end: Time the running command's lease ends [s].
        ignored: Messages not acted on: ``duplicate``, ``stale``, ``retired`` (from a retired session),
            ``refused`` (another session while the served one is live), ``copy``, ``bad_lease``, ``late``
            (deadline already past), ``boot`` (deadline for another boot); ``foreign_stop`` counts STOPs
            from sessions other than the served one (they do halt the fins).
        crc_errors: Frames rejected by the caller's decoder, reported back in STATUS (set by the caller).
    """

    def __init__(self, config: FirmwareConfig | None = None, boot: int | None = None, power_up: float = 0.0):
        self.config = config or FirmwareConfig()
        self.boot = new_boot_id() if boot is None else int(boot) & 0xFFFFFFFF
        if self.boot == 0:
            raise ValueError("boot id must be nonzero (0 means 'no deadline' in a SET_FINS)")
        self.power_up = float(power_up)
        self.state = RobotState.IDLE
        self.command = rest_beats()
        self.setpoint = rest_beats()
        self.halt = False
        self.clipped = False
        self.tracker = SequenceTracker()
        self.crc_errors = 0
        self.session: int | None = None
        self.retired: list[int] = []
        self.command_id: int | None = None
        self.handed: np.ndarray | None = None
        self.handed_id: int | None = None
        self.lease_end = -math.inf
        self.ignored = dict.fromkeys(("duplicate", "stale", "retired", "refused", "copy", "bad_lease", "late", "boot",
                                      "foreign_stop"), 0)
        self._seq = 0
        self._latch_seq = 0  # LATCH messages are numbered on their own: a PC that drops them sees no STATUS gap
        self._held_back = np.zeros(2, dtype=bool)  # per fin: its last latch ran less than the command (rate rule)
        self.last_valid: float | None = None  # time of the last new, valid message of the session [s]
        self.tripped_at: float | None = None  # time the watchdog or the lease last stopped the fins [s]

    @property
    def running(self) -> bool:
        """Whether the fins are beating."""
        return self.state == RobotState.RUNNING

    def _status(self, ack: Message, now: float) -> Message:
        self._seq = (self._seq + 1) & 0xFFFF
        flags = (StatusFlag.CLIPPED if self.clipped else 0) | (
            StatusFlag.RATE_LIMITED if self.running and self._held_back.any() else 0)
        status = Status(ack.seq, int(ack.type), int(self.state), int(flags), self.crc_errors,
                        self.tracker.duplicates, self.tracker.stale, self.uptime_ms(now),
                        0 if self.session is None else self.session, self.boot)
        return Message(MsgType.STATUS, self._seq, ack.session, status=status)  # addressed to the asker

    def latch_report(self, t: float, fin: int, beat: np.ndarray, turn: float, power: bool) -> Message | None:
        """The LATCH to send when fin ``fin`` latched ``beat`` at time ``t`` [s] (``None``: nothing to send).

        Sent while running, for every half-stroke that moves: a half-stroke that ends where it starts (a still
        fin) moves nothing; the next report carries all a replay needs.

        Args:
            t: When the fin latched (its stroke turning point) [s, the caller's clock].
            fin: 0 right, 1 left.
            beat: ``(bias, amplitude, period, ratio)`` the fin runs from there (rad, rad, s, -).
            turn: The fin angle at the turning point [rad].
            power: Whether the half-stroke that starts is a power stroke.
        """
        if not self.running or self.session is None:
            return None  # halted fins hold still: nothing latches that a replay needs
        # bias, amplitude and ratio: the period may be stretched for the transition, which is not the rate rule
        ran = np.asarray(beat, dtype=float)[[0, 1, 3]]
        self._held_back[int(fin)] = not np.allclose(ran, self.command[int(fin), [0, 1, 3]])
        bias, amplitude = float(beat[0]), float(beat[1])
        if (bias + amplitude if power else bias - amplitude) == float(turn):
            return None  # a half-stroke that ends where it starts moves nothing (a still fin's)
        self._latch_seq = (self._latch_seq + 1) & 0xFFFF
        latch = Latch(self.uptime_ms(t), self.boot, int(fin), bool(power), float(turn),
                      tuple(float(v) for v in np.asarray(beat, dtype=float).reshape(4)))
        return Message(MsgType.LATCH, self._latch_seq, self.session, latch=latch)

    def uptime_ms(self, now: float) -> int:
        """The robot clock [ms since power-up, u32, rounded down with the :data:`MS_GUARD`] at ``now`` [s]."""
        return int(math.floor(1000.0 * max(now - self.power_up, 0.0) + MS_GUARD)) & 0xFFFFFFFF

    def _clock_ms(self, t: float) -> float:
        """``t`` [s] as a whole ms since power-up (not wrapped; an infinite ``t`` stays infinite)."""
        return math.floor(1000.0 * (t - self.power_up) + MS_GUARD) if math.isfinite(t) else t

    def _admit(self, msg: Message, now: float) -> bool:
        """Whether a message of a session other than the served one takes the robot over (then it does)."""
        if msg.session in self.retired:
            self.ignored["retired"] += 1
            return False
        silent = (self.last_valid is None
                  or self._clock_ms(now) - self._clock_ms(self.last_valid) >= 1000.0 * self.config.watchdog_timeout)
        if self.session is not None and not silent and msg.type != MsgType.CLAIM:
            self.ignored["refused"] += 1  # the served session is live: taking over needs a CLAIM
            return False
        if self.session is not None:
            self.retired = [*self.retired[-(_RETIRED - 1):], self.session]
            if self.running:
                self._stop(RobotState.STOPPED)  # the new controller must command anew
        self.session, self.command_id, self.last_valid = msg.session, None, None
        self.tracker = SequenceTracker()
        return True

    def receive(self, msg: Message, now: float) -> Message | None:
        """Handle a valid message received at ``now`` [s]; return the STATUS reply, or ``None`` (ignored)."""
        if msg.type in (MsgType.STATUS, MsgType.LATCH):
            return None  # the robot's own kinds: not for us
        if msg.session != self.session and not self._admit(msg, now):
            if msg.type == MsgType.STOP:  # a stop never needs authority
                self.ignored["foreign_stop"] += 1
                self._stop(RobotState.STOPPED)
            return self._status(msg, now)  # refused, but answered: the sender learns whom the robot serves
        verdict = self.tracker.check(msg.seq, msg.session)
        if verdict == Verdict.STALE:
            self.ignored["stale"] += 1
            return None
        if verdict == Verdict.DUPLICATE:
            self.ignored["duplicate"] += 1  # acknowledged, nothing else: no liveness from a repeat
            return self._status(msg, now)
        self.last_valid = now
        if msg.type == MsgType.STOP:
            self._stop(RobotState.STOPPED)
        elif msg.type == MsgType.SET_FINS:
            self._set_fins(msg, now)
        return self._status(msg, now)

    def _set_fins(self, msg: Message, now: float) -> None:
        if not 0 < msg.lease <= self.config.max_lease:
            self.ignored["bad_lease"] += 1
            return
        if self.command_id is not None and not serial_newer(msg.command, self.command_id):
            self.ignored["copy"] += 1  # a copy (or an older command): it neither extends nor restarts
            return
        self.command_id = msg.command
        now_ms = self._clock_ms(now)
        end_ms = now_ms + round(msg.lease * 1000.0)  # counted from our own receipt of the first copy
        if msg.deadline:
            if msg.boot != self.boot:
                self.ignored["boot"] += 1  # a deadline on another power-up's clock: meaningless here
                return
            ahead_ms = ((msg.deadline - self.uptime_ms(now) + 0x80000000) & 0xFFFFFFFF) - 0x80000000
            end_ms = min(end_ms, now_ms + ahead_ms)  # u32 wrap-safe
        end = self.power_up + end_ms / 1000.0
        if end_ms <= now_ms:
            self.ignored["late"] += 1  # this command's time is over: never start it, stop the previous one
            if self.running:
                self._stop(RobotState.EXPIRED)
                self.tripped_at = now
            return
        self.lease_end = end
        fins = np.asarray(msg.fins, dtype=float).reshape(2, 4)
        self.command, self.clipped = clip_beats(fins, self.config.limits)
        if not self.running:
            self.setpoint = self.setpoint.copy()
            self.state = RobotState.RUNNING

    def _stop(self, state: RobotState) -> None:
        if self.running:
            self.halt = True
        self.state = state

    def tick(self, now: float, fin_angles: np.ndarray | None = None) -> None:
        """Advance the rules to ``now`` [s]: lease, watchdog, the setpoint.

        Args:
            now: Current time [s].
            fin_angles: Current fin angles ``(2,)`` [rad]; a halted fin's setpoint is rest at its angle.
        """
        now_ms = self._clock_ms(now)
        if self.running and now_ms >= self._clock_ms(self.lease_end):
            self._stop(RobotState.EXPIRED)
            self.tripped_at = now
        if (self.running and self.last_valid is not None
                and now_ms - self._clock_ms(self.last_valid) > 1000.0 * self.config.watchdog_timeout):
            self._stop(RobotState.WATCHDOG)
            self.tripped_at = now
        if self.running:
            self.setpoint = self.command.copy()  # rate-limited where the fins latch it (slew_at_latch)
        elif fin_angles is not None:
            self.setpoint = rest_beats(fin_angles)
