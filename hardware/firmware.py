"""The robot-side rules as a pure state machine (what the dsPIC firmware must do; ``docs/protocol.md``).

:class:`Firmware` knows nothing of sockets, clocks or physics: the caller hands it decoded messages
and the time, and reads back the fin setpoint, whether the fins must halt, and the STATUS replies.
The emulator drives a :class:`~pectoral_gym.models.FullModel` with it; the same rules are the
specification of the real firmware. The fin itself latches a new setpoint at its next stroke turning
point (the parameter-change rule of the core models, reused by the emulator through
``FullModel.command``); a halt is immediate (the servos hold their current angle).

Rules:

* **Watchdog**: no valid message for ``watchdog_timeout`` (default 0.5 s) -> state ``WATCHDOG``, fins
  halt. Only a new SET_FINS starts them again.
* **STOP** -> state ``STOPPED``, fins halt at once.
* **Clipping** to :class:`ServoLimits`: stroke ``bias +- amplitude`` inside the servo's angle range,
  period and ratio inside theirs, and the power-stroke speed ``2 amplitude (ratio + 1) / period``
  at most ``max_speed`` (the period is lengthened).
* **Rate limiting**: the setpoint slews towards the clipped command at most ``max_rate`` per second
  and parameter.
* **Sequence numbers**: new -> act and acknowledge; duplicate -> acknowledge only (a retry whose first
  copy arrived); stale -> ignore. All counted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hardware.protocol import Message, MsgType, RobotState, SequenceTracker, Status, StatusFlag, Verdict

__all__ = ["ServoLimits", "FirmwareConfig", "Firmware", "clip_beats", "rate_limit", "rest_beats"]


def _default_rate() -> tuple[float, float, float, float]:
    return (math.radians(180.0), math.radians(180.0), 4.0, 10.0)


@dataclass(frozen=True)
class ServoLimits:
    """What the fin servos can do; commands are clipped to these (PC side and robot side alike).

    Defaults admit every pattern of the simulated environments' default action ranges unchanged.

    Attributes:
        angle_min: Smallest fin angle [rad] (stroke ``bias - amplitude``).
        angle_max: Largest fin angle [rad] (stroke ``bias + amplitude``).
        period_min: Shortest fin-beat period [s].
        period_max: Longest fin-beat period [s].
        ratio_min: Smallest power/recovery speed ratio [-].
        ratio_max: Largest ratio [-].
        max_speed: Fastest fin angular speed [rad/s] (power stroke ``2 A (zeta + 1) / T_p``).
        max_rate: Largest change per second of (bias [rad/s], amplitude [rad/s], period [s/s], ratio [1/s]).
    """

    angle_min: float = math.radians(10.0)
    angle_max: float = math.radians(170.0)
    period_min: float = 0.4
    period_max: float = 4.0
    ratio_min: float = 0.5
    ratio_max: float = 6.0
    max_speed: float = 13.0
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


def rest_beats(angles: np.ndarray | None = None) -> np.ndarray:
    """``(2, 4)`` fins held still at ``angles`` (default 90 deg): amplitude 0, period 1 s, ratio 1."""
    angles = np.full(2, math.pi / 2) if angles is None else np.asarray(angles, dtype=float)
    return np.stack([np.array([a, 0.0, 1.0, 1.0]) for a in angles])


def clip_beats(beats: np.ndarray, limits: ServoLimits) -> tuple[np.ndarray, bool]:
    """Clip ``(2, 4)`` fin patterns to ``limits``; returns ``(clipped, changed)``. Input must be finite."""
    b = np.array(beats, dtype=float).reshape(2, 4)
    out = b.copy()
    half_range = 0.5 * (limits.angle_max - limits.angle_min)
    out[:, 1] = np.clip(out[:, 1], 0.0, half_range)
    out[:, 0] = np.clip(out[:, 0], limits.angle_min + out[:, 1], limits.angle_max - out[:, 1])
    out[:, 2] = np.clip(out[:, 2], limits.period_min, limits.period_max)
    out[:, 3] = np.clip(out[:, 3], limits.ratio_min, limits.ratio_max)
    speed = 2.0 * out[:, 1] * (out[:, 3] + 1.0) / out[:, 2]  # power-stroke speed, eq. (21)
    too_fast = speed > limits.max_speed
    if np.any(too_fast):
        slow_period = 2.0 * out[:, 1] * (out[:, 3] + 1.0) / limits.max_speed
        out[:, 2] = np.where(too_fast, slow_period, out[:, 2])
        # A period beyond period_max cannot slow the stroke enough: shrink the amplitude instead.
        over = out[:, 2] > limits.period_max
        out[:, 2] = np.minimum(out[:, 2], limits.period_max)
        out[:, 1] = np.where(over, limits.max_speed * out[:, 2] / (2.0 * (out[:, 3] + 1.0)), out[:, 1])
    return out, bool(np.any(np.abs(out - b) > 1e-12))


def rate_limit(current: np.ndarray, target: np.ndarray, dt: float, limits: ServoLimits) -> np.ndarray:
    """Move ``current`` towards ``target`` by at most ``max_rate * dt`` per parameter (both ``(2, 4)``)."""
    step = np.asarray(limits.max_rate, dtype=float) * max(float(dt), 0.0)
    return np.asarray(current, float) + np.clip(np.asarray(target, float) - current, -step, step)


@dataclass(frozen=True)
class FirmwareConfig:
    """Settings of the robot-side rules.

    Attributes:
        watchdog_timeout: Halt the fins after this long without a valid message [s]; at most 1 s.
        limits: Servo limits for clipping and rate limiting.
    """

    watchdog_timeout: float = 0.5
    limits: ServoLimits = field(default_factory=ServoLimits)

    def __post_init__(self) -> None:
        if not 0 < self.watchdog_timeout <= 1.0:
            raise ValueError(f"watchdog_timeout must be in (0, 1] s, got {self.watchdog_timeout!r}")


class Firmware:
    """The robot's rules, driven by :meth:`receive` (messages) and :meth:`tick` (time).

    Attributes:
        state: A :class:`RobotState`.
        command: ``(2, 4)`` the last accepted SET_FINS, clipped to the servo limits.
        setpoint: ``(2, 4)`` the rate-limited pattern the fins should follow (valid while running).
        halt: Set when the fins must stop at once; the caller clears it after halting them.
        tracker: Sequence bookkeeping of the PC's messages.
        crc_errors: Frames rejected by the caller's decoder, reported back in STATUS (set by the caller).
    """

    def __init__(self, config: FirmwareConfig | None = None):
        self.config = config or FirmwareConfig()
        self.state = RobotState.IDLE
        self.command = rest_beats()
        self.setpoint = rest_beats()
        self.halt = False
        self.clipped = False
        self.tracker = SequenceTracker()
        self.crc_errors = 0
        self._seq = 0
        self.last_valid: float | None = None  # time of the last valid, non-stale message [s]
        self.tripped_at: float | None = None  # time the watchdog last fired [s]
        self._last_tick: float | None = None
        self._start: float | None = None

    @property
    def running(self) -> bool:
        """Whether the fins are beating."""
        return self.state == RobotState.RUNNING

    def _status(self, ack: Message, now: float) -> Message:
        self._seq = (self._seq + 1) & 0xFFFF
        flags = (StatusFlag.CLIPPED if self.clipped else 0) | (
            StatusFlag.RATE_LIMITED if self.running and not np.allclose(self.setpoint, self.command) else 0)
        start = self._start if self._start is not None else now
        status = Status(ack.seq, int(ack.type), int(self.state), int(flags), self.crc_errors,
                        self.tracker.duplicates, self.tracker.stale, int(1000 * (now - start)) & 0xFFFFFFFF)
        return Message(MsgType.STATUS, self._seq, 0, status=status)

    def receive(self, msg: Message, now: float) -> Message | None:
        """Handle a valid message received at ``now`` [s]; return the STATUS reply, or ``None`` (stale)."""
        if msg.type == MsgType.STATUS:
            return None  # not for us
        if self._start is None:
            self._start = now
        verdict = self.tracker.check(msg.seq, msg.session)
        if verdict == Verdict.STALE:
            return None
        self.last_valid = now  # any valid, non-stale message feeds the watchdog
        if verdict == Verdict.NEW:
            if msg.type == MsgType.STOP:
                self._stop(RobotState.STOPPED)
            elif msg.type == MsgType.SET_FINS:
                fins = np.asarray(msg.fins, dtype=float).reshape(2, 4)
                self.command, self.clipped = clip_beats(fins, self.config.limits)
                if not self.running:
                    self.setpoint = self.setpoint.copy()
                    self.state = RobotState.RUNNING
        return self._status(msg, now)

    def _stop(self, state: RobotState) -> None:
        if self.running:
            self.halt = True
        self.state = state

    def tick(self, now: float, fin_angles: np.ndarray | None = None) -> None:
        """Advance the rules to ``now`` [s]: watchdog, rate limiting.

        Args:
            now: Current time [s].
            fin_angles: Current fin angles ``(2,)`` [rad]; a halted fin's setpoint is rest at its angle.
        """
        dt = 0.0 if self._last_tick is None else now - self._last_tick
        self._last_tick = now
        if (self.running and self.last_valid is not None
                and now - self.last_valid > self.config.watchdog_timeout):
            self._stop(RobotState.WATCHDOG)
            self.tripped_at = now
            self.tracker.reset()  # the PC may have restarted with a new sequence
        if self.running:
            slewed = rate_limit(self.setpoint, self.command, dt, self.config.limits)
            self.setpoint = clip_beats(slewed, self.config.limits)[0]  # per-parameter slewing may leave the limits
        elif fin_angles is not None:
            self.setpoint = rest_beats(fin_angles)
