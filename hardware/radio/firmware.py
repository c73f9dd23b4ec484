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
* **Clipping** to :class:`~pectoral_gym.model.servo.ServoLimits`: stroke ``bias +- amplitude`` inside the servo's
  angle range, period and ratio inside theirs, and the *peak* fin rate of both half-strokes at most ``max_speed``
  (the period is lengthened, :func:`~pectoral_gym.model.servo.clip_beats`); the transitional half-stroke from the
  fin's next turning point is bounded the same way (:func:`~pectoral_gym.model.finrules.stretch_transition`,
  applied where the fin latches). The fin rules are :mod:`pectoral_gym.model.finrules`' (the core's, which the
  emulator, the PC's replay, the backup shield and the calibration run too); this module is their state machine.
* **Rate limiting, per latch**: the pattern a moving fin latches at a turning point differs from the one it
  ran by at most ``max_rate`` per parameter times that half-stroke's duration
  (:func:`~pectoral_gym.model.finrules.slew_at_latch`); a still fin latches the command, its first half-stroke
  from rest bounded by ``max_speed`` (above). The fins only ever run latched patterns, so a moving fin's pattern
  changes at most ``max_rate`` per second, as a per-tick slew of the setpoint bounds it; but what a turning point
  latches does not depend on the milliseconds between a command's arrival and the firmware's tick, so the PC's
  replay knows it (``docs/hardware.md``, "The firmware's rate rule").
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
from pectoral_gym.model.finrules import FinState, FirmwareConfig

__all__ = ["MS_GUARD", "Firmware", "new_boot_id"]

_RETIRED = 16  # sessions remembered as retired (a restarted PC gets a fresh random 32-bit session)
#: A time within this many ms below a whole millisecond counts as that millisecond (1 us: above float64's rounding
#: of a time and the robot's float32 turning points, far below anything a millisecond clock resolves).
MS_GUARD = 1e-3


def new_boot_id(rng=None) -> int:
    """A random nonzero 32-bit boot id (from ``rng``, a numpy ``Generator``, if given; else the OS's source)."""
    boot = int(rng.integers(0, 2**32)) if rng is not None else secrets.randbits(32)
    return boot or 1


class Firmware(FinState):
    """The robot's rules, driven by :meth:`receive` (messages) and :meth:`tick` (time).

    The session, lease, watchdog and sequence rules are this class's; the fins' side (the command clipped, the
    setpoint, the halt, the hand-over bookkeeping) is :class:`~pectoral_gym.model.finrules.FinState`'s.

    Args:
        config: The rules' settings.
        boot: This power-up's boot id (nonzero; default: a fresh random one, :func:`new_boot_id`).
        power_up: The caller's clock at power-up [s]: the uptime reported in STATUS counts from it.

    Attributes:
        state: A :class:`RobotState`.
        command: ``(2, 4)`` the last accepted SET_FINS, clipped to the servo limits.
        setpoint: ``(2, 4)`` the pattern the fins should run (valid while running): the command, or rest where
            halted fins hold still; what a turning point latches of it is
            :func:`~pectoral_gym.model.finrules.next_latch`'s.
        halt: Set when the fins must stop at once; the caller clears it after halting them.
        tracker: Sequence bookkeeping of the current session's messages.
        session: The session served (``None`` before the first message).
        command_id: Identity of the last command run (``None`` before the first).
        handed: ``(2, 4)`` the pattern last handed to the fins and ``handed_id`` the command it came from
            (``None``: nothing handed since power-up or a halt; :func:`~pectoral_gym.model.finrules.apply_firmware`).
        lease_end: Time the running command's lease ends [s].
        ignored: Messages not acted on: ``duplicate``, ``stale``, ``retired`` (from a retired session),
            ``refused`` (another session while the served one is live), ``copy``, ``bad_lease``, ``late``
            (deadline already past), ``boot`` (deadline for another boot); ``foreign_stop`` counts STOPs
            from sessions other than the served one (they do halt the fins).
        crc_errors: Frames rejected by the caller's decoder, reported back in STATUS (set by the caller).
    """

    def __init__(self, config: FirmwareConfig | None = None, boot: int | None = None, power_up: float = 0.0):
        super().__init__(config)
        self.boot = new_boot_id() if boot is None else int(boot) & 0xFFFFFFFF
        if self.boot == 0:
            raise ValueError("boot id must be nonzero (0 means 'no deadline' in a SET_FINS)")
        self.power_up = float(power_up)
        self.state = RobotState.IDLE
        self.tracker = SequenceTracker()
        self.crc_errors = 0
        self.session: int | None = None
        self.retired: list[int] = []
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
        self.accept(np.asarray(msg.fins, dtype=float))
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
        self.update_setpoint(fin_angles)
