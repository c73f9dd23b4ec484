"""PC-side safety rules of the hardware environment (the robot's own: :mod:`~pectoral_gym.hardware.radio.firmware`).

* :class:`SafetyConfig`: the settings of all of them.
* :func:`check_action`: a non-finite action is rejected before anything is sent.
* :class:`CommandFilter`: commands clipped to the servo limits and rate-limited per control step.
* :class:`~pectoral_gym.hardware.safety.geofence.Geofence` and its
  :class:`~pectoral_gym.hardware.safety.geofence.SpeedBound` (in :mod:`pectoral_gym.hardware.safety.geofence`):
  the fish too close to a wall to stop in time -> stop, end the episode.
* :class:`TrackingWatch`: tracking lost for longer than ``timeout`` -> stop, end the episode.
* :func:`effective_reaction_time`: the geofence's reaction time on a radio that delays the STOP.
* :func:`install_stop_handlers`: Ctrl-C and SIGTERM send stop before the program ends.

:class:`pectoral_gym.hardware.safety.supervisor.Supervisor` applies these rules in its own thread, also between steps;
:class:`pectoral_gym.hardware.vision.framecheck.FrameCheck` decides which camera frames count as a sighting.
"""

from __future__ import annotations

import math
import signal
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pectoral_gym.hardware.radio.protocol import DEFAULT_LEASE, MAX_LEASE
from pectoral_gym.model import tank
from pectoral_gym.model.finrules import rate_limit, stretch_transition
from pectoral_gym.model.servo import ServoLimits, clip_beats

#: The longest tracking timeout a :class:`SafetyConfig` accepts [s].
MAX_TRACKING_TIMEOUT = 5.0

__all__ = ["MAX_TRACKING_TIMEOUT", "SafetyConfig", "check_action", "CommandFilter", "TrackingWatch",
           "effective_reaction_time", "install_stop_handlers"]


@dataclass(frozen=True)
class SafetyConfig:
    """PC-side safety settings.

    Attributes:
        limits: Servo limits (clipping and rate limiting), shared with the firmware rules.
        stop_rule: The geofence's :class:`~pectoral_gym.model.tank.StopRule`: the clearance kept from every wall on
            top of the stopping distance [m], the reaction time from a pose to the fins halting (frame age, polling,
            radio) [s], and the contact speed [m/s] the fish crosses the margin line no faster than after a stop.
            Default: the robot's, :data:`~pectoral_gym.model.tank.ROBOT_STOP_RULE`.
        tracking_timeout: Stop when the fish has not been seen for this long [s]; in
            ``(0, MAX_TRACKING_TIMEOUT]`` (while the fish is unseen the geofence also assumes the worst motion
            the fins allow).
        link_timeout: Stop when the robot has not answered for this long [s].
        lease: Lease of each command from ``step()`` [s]: the robot stops this long after it receives a
            command unless a new one comes (``docs/protocol.md``); at most ``protocol.MAX_LEASE``.
        step_slack: Time allowed between the end of one ``step()`` and the start of the next (policy
            compute time, timing jitter) [s]; ``step()`` renews the lease only while it runs, to last
            this long past its own end.
        max_frame_lead: Camera timestamps further ahead of this machine's clock are rejected [s].
        pose_noise: Standard deviation of the tracked position assumed for the geofence's speed estimate [m]
            (the fit's own scatter is used when larger).
    """

    limits: ServoLimits = field(default_factory=ServoLimits)
    stop_rule: tank.StopRule = tank.ROBOT_STOP_RULE
    tracking_timeout: float = 0.5
    link_timeout: float = 1.0
    lease: float = DEFAULT_LEASE
    step_slack: float = 0.3
    max_frame_lead: float = 0.05
    pose_noise: float = 0.005

    def __post_init__(self) -> None:
        if not isinstance(self.stop_rule, tank.StopRule):
            raise ValueError(f"SafetyConfig.stop_rule must be a pectoral_gym.model.tank.StopRule, got "
                             f"{self.stop_rule!r}")
        for name in ("tracking_timeout", "link_timeout", "lease", "step_slack", "max_frame_lead", "pose_noise"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"SafetyConfig.{name} must be a finite number >= 0, got {value!r}")
        if self.tracking_timeout <= 0:
            raise ValueError(f"SafetyConfig.tracking_timeout must be > 0 s, got {self.tracking_timeout!r}")
        if self.tracking_timeout > MAX_TRACKING_TIMEOUT:
            raise ValueError(f"SafetyConfig.tracking_timeout = {self.tracking_timeout} s exceeds "
                             f"MAX_TRACKING_TIMEOUT = {MAX_TRACKING_TIMEOUT} s (a fish unseen that long is lost)")
        if not 0 < self.step_slack < self.lease <= MAX_LEASE:
            raise ValueError(f"SafetyConfig: need 0 < step_slack < lease <= {MAX_LEASE} s, got "
                             f"{self.step_slack}, {self.lease}")


def check_action(action, size: int = 8) -> np.ndarray:
    """``action`` as a float64 array of ``size``; ``ValueError`` if it has another shape or is not finite."""
    try:
        if np.iscomplexobj(action):
            raise TypeError("complex")  # the imaginary part would be dropped silently
        arr = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"action must be {size} numbers, got {action!r}") from None
    if arr.shape != (size,):
        raise ValueError(f"action must have shape ({size},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"action must be finite, got {arr.tolist()}; nothing was sent to the robot")
    return arr


class CommandFilter:
    """Clip fin commands ``(2, 4)`` to the servo limits and rate-limit them between successive calls.

    Mirrors the firmware: the peak rate of every half-stroke (:func:`pectoral_gym.model.servo.clip_beats`)
    and of the transitional half-stroke into the new pattern from either turning point of the previous command
    (:func:`pectoral_gym.model.finrules.stretch_transition`) stays within ``limits.max_speed``.

    Args:
        limits: Servo limits.

    Attributes:
        last: The last command let through (``None`` before the first).
        clipped, rate_limited: Whether the last call changed the command for either reason.
    """

    def __init__(self, limits: ServoLimits):
        self.limits = limits
        self.last: np.ndarray | None = None
        self.clipped = self.rate_limited = False

    def reset(self, beats: np.ndarray | None = None) -> None:
        """Forget the history (the next command is only clipped), or start from ``beats``."""
        self.last = None if beats is None else np.asarray(beats, dtype=float).reshape(2, 4).copy()

    def __call__(self, beats: np.ndarray, dt: float) -> np.ndarray:
        """The command to send for ``beats`` after ``dt`` seconds since the previous one."""
        clipped, self.clipped = clip_beats(beats, self.limits)
        out = clipped if self.last is None else rate_limit(self.last, clipped, dt, self.limits)
        out = clip_beats(out, self.limits)[0]
        if self.last is not None:
            for turn in (self.last[:, 0] - self.last[:, 1], self.last[:, 0] + self.last[:, 1]):
                for power in (False, True):
                    out = stretch_transition(out, turn, np.full(2, power), self.limits)
        self.rate_limited = bool(np.any(np.abs(out - clipped) > 1e-12))
        self.last = out
        return out.copy()


class TrackingWatch:
    """How long the fish has gone unseen.

    Args:
        timeout: Lost longer than this [s] -> :meth:`expired`.
    """

    def __init__(self, timeout: float):
        self.timeout = float(timeout)
        self.last_seen: float | None = None
        self.reason = ""

    def reset(self, now: float) -> None:
        """Start watching at ``now`` as if the fish had just been seen."""
        self.last_seen, self.reason = now, ""

    def update(self, now: float, ok: bool, reason: str = "") -> None:
        """Record a tracking result at ``now``: seen (``ok``) or not (``reason``)."""
        if ok:
            self.last_seen, self.reason = now, ""
        elif reason:
            self.reason = reason

    def lost_for(self, now: float) -> float:
        """Seconds since the fish was last seen."""
        return math.inf if self.last_seen is None else max(0.0, now - self.last_seen)

    def expired(self, now: float) -> bool:
        """Whether the fish has been lost for longer than ``timeout``."""
        return self.lost_for(now) > self.timeout


def effective_reaction_time(rule: tank.StopRule, round_trip: float | None) -> float:
    """The time from a pose to the fins halting [s] on a radio whose measured round trip is ``round_trip`` [s].

    The rule's reaction time ``t_r`` (``SafetyConfig.stop_rule``) budgets a prompt radio: frame age,
    polling, a few milliseconds of air time. A STOP decided now reaches the robot one forward delay ``f`` later,
    and the fins run until then; the PC cannot measure ``f`` alone (``docs/protocol.md`` section 5: a radio slow
    one way and one slow both ways give it identical times), but the return delay is not negative, so
    ``f <= RTT``. Hence ``t_r + round_trip``, the bound the geofence's stopping distance needs
    (``docs/guide/safety.md``, "The radio's delay and the geofence").

    It covers the STOP's first copy. A lost copy is sent again (the link's retry, and its keep-alive repeats STOP
    every 0.1 s until the robot reports still), each adding that period with the loss's probability; the robot
    halts by itself at its lease's end in any case (``docs/protocol.md`` section 5).

    Args:
        rule: The geofence's :class:`~pectoral_gym.model.tank.StopRule` (its ``reaction_time``: the prompt radio's).
        round_trip: The link's measured round trip [s] (its smoothed estimate), >= 0; ``None`` before the first
            sample gives ``t_r`` alone: until the first command's STATUS returns, the fins have run for
            less than one round trip from rest, and the speed bound (``SpeedBound``) holds the fish's speed to
            what that short run can give.
    """
    reaction = rule.reaction_time
    if round_trip is None:
        return reaction
    rtt = float(round_trip)
    if not (math.isfinite(rtt) and rtt >= 0):
        raise ValueError(f"round_trip must be a finite number of seconds >= 0 or None, got {round_trip!r}")
    return reaction + rtt


def install_stop_handlers(stop: Callable[[], object]) -> Callable[[], None]:
    """Make SIGINT (Ctrl-C) and SIGTERM call ``stop()`` before the usual ending; returns a function that undoes it.

    ``stop`` runs inside the signal handler, so it must take no lock (``HardwareFishEnv.stop`` and
    ``RadioLink.emergency_stop`` qualify). Then the handler that was installed before runs; if that was
    the default, SIGINT raises ``KeyboardInterrupt`` and SIGTERM ``SystemExit(143)``, so ``finally``
    blocks and ``close()`` still run. Outside the main thread nothing is installed (Python allows
    signal handlers only there).
    """
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}

    def handler(signum, frame):
        try:
            stop()
        finally:
            old = previous.get(signum)
            if callable(old):
                old(signum, frame)
            elif old != signal.SIG_IGN:
                if signum == signal.SIGINT:
                    raise KeyboardInterrupt
                raise SystemExit(128 + signum)

    for sig in previous:
        signal.signal(sig, handler)

    def restore() -> None:
        for sig, old in previous.items():
            if signal.getsignal(sig) is handler:  # not if someone installed their own on top since
                signal.signal(sig, old)

    return restore
