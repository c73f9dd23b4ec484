"""PC-side safety rules of the hardware environment (the robot enforces its own in :mod:`hardware.firmware`).

* :func:`check_action`: a non-finite action is rejected before anything is sent.
* :class:`CommandFilter`: commands clipped to the servo limits and rate-limited per control step.
* :class:`Geofence`: any part of the fish (body and fin tips) closer to a wall than it needs to stop
  (reaction distance plus the coasting distance of eq. (19) with the fins still) -> stop, end the episode;
  :func:`in_geofence` is the older nose-and-tail test.
* :class:`TrackingWatch`: tracking lost for longer than ``timeout`` -> stop, end the episode.
* :func:`install_stop_handlers`: Ctrl-C and SIGTERM send stop before the program ends.

:class:`hardware.supervisor.Supervisor` applies these rules in its own thread, also between steps;
:class:`hardware.framecheck.FrameCheck` decides which camera frames count as a sighting.
"""

from __future__ import annotations

import math
import signal
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hardware.firmware import ServoLimits, clip_beats, rate_limit, stretch_transition
from hardware.protocol import DEFAULT_LEASE, MAX_LEASE
from pectoral_gym.params import TANK_LENGTH, TANK_WIDTH, FishParams, body_coefficients

__all__ = ["SafetyConfig", "check_action", "CommandFilter", "Geofence", "in_geofence", "TrackingWatch",
           "install_stop_handlers"]


@dataclass(frozen=True)
class SafetyConfig:
    """PC-side safety settings.

    Attributes:
        limits: Servo limits (clipping and rate limiting), shared with the firmware rules.
        geofence_margin: Clearance kept from every wall on top of the stopping distance [m].
        tracking_timeout: Stop when the fish has not been seen for this long [s].
        link_timeout: Stop when the robot has not answered for this long [s].
        lease: Lease of each command from ``step()`` [s]: the robot stops this long after it receives a
            command unless a new one comes (``docs/protocol.md``); at most ``protocol.MAX_LEASE``.
        step_slack: Time allowed between the end of one ``step()`` and the start of the next (policy
            compute time, timing jitter) [s]; ``step()`` renews the lease only while it runs, to last
            this long past its own end.
        coast_horizon: The geofence keeps the fish off the walls for this long after a stop [s].
        reaction_time: Time from a pose to the fins halting (frame age, polling, radio) [s].
        max_frame_lead: Camera timestamps further ahead of this machine's clock are rejected [s].
    """

    limits: ServoLimits = field(default_factory=ServoLimits)
    geofence_margin: float = 0.05
    tracking_timeout: float = 0.5
    link_timeout: float = 1.0
    lease: float = DEFAULT_LEASE
    step_slack: float = 0.3
    coast_horizon: float = 5.0
    reaction_time: float = 0.15
    max_frame_lead: float = 0.05

    def __post_init__(self) -> None:
        for name in ("geofence_margin", "tracking_timeout", "link_timeout", "lease", "step_slack", "coast_horizon",
                     "reaction_time", "max_frame_lead"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"SafetyConfig.{name} must be a finite number >= 0, got {value!r}")
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

    Mirrors the firmware: the peak rate of every half-stroke (:func:`hardware.firmware.clip_beats`) and of
    the transitional half-stroke into the new pattern from either turning point of the previous command
    (:func:`hardware.firmware.stretch_transition`) stays within ``limits.max_speed``.

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


class Geofence:
    """Whether the fish can still stop before any part of it reaches a wall.

    The outline is a capsule from nose to tail of radius ``C_p`` (the body width) and a disc of radius
    ``S_p`` around each fin pivot ``(0, +-C_p)`` (the fin tip wherever the fin points). Per wall, the
    clearance of the outline must exceed ``margin + v t_r + d_coast(v)`` with ``v`` the speed towards
    that wall, ``t_r`` the reaction time and the coasting distance with the fins still: eq. (19) with no
    fin force and the motion along one axis is ``m dv/dt = -c1 v |v|``, so
    ``v(t) = v0 / (1 + k v0 t)`` and ``d(T) = ln(1 + k v0 T) / k`` with ``k = c1 / m`` (``docs/model.md``,
    body coefficients), ``m`` the larger of ``m1, m2`` (the slower decay). Yaw coupling is neglected;
    ``margin`` covers it.

    Args:
        params: Fish geometry and body coefficients.
        margin: Clearance on top of the stopping distance [m].
        reaction_time: ``t_r`` [s].
        horizon: ``T`` [s]: the fish stays clear for this long after the stop.
    """

    def __init__(self, params: FishParams, margin: float, reaction_time: float, horizon: float):
        coef = body_coefficients(params)
        self.k = coef.c1 / max(coef.m1, coef.m2)  # [1/m]
        self.half_length, self.width, self.span = 0.5 * params.body_length, params.fin_offset, params.fin_span
        self.margin, self.reaction_time, self.horizon = float(margin), float(reaction_time), float(horizon)

    def coast(self, speed: float) -> float:
        """Distance [m] covered in ``horizon`` s by a fish coasting from ``speed`` [m/s] with its fins still."""
        v = max(float(speed), 0.0)
        return math.log1p(self.k * v * self.horizon) / self.k

    def outline(self, x: float, y: float, psi: float) -> tuple[np.ndarray, np.ndarray]:
        """Centres ``(4, 2)`` (nose, tail, right and left fin pivot) and radii ``(4,)`` of the outline [m]."""
        c, s = math.cos(psi), math.sin(psi)
        body = np.array([[self.half_length, 0.0], [-self.half_length, 0.0], [0.0, -self.width], [0.0, self.width]])
        centres = np.array([x, y]) + body @ np.array([[c, s], [-s, c]])
        return centres, np.array([self.width, self.width, self.span, self.span])

    def clearance(self, x: float, y: float, psi: float) -> np.ndarray:
        """Distance [m] from the outline to the walls ``X = 0, X = L, Y = 0, Y = W`` (negative: across)."""
        p, r = self.outline(x, y, psi)
        return np.array([np.min(p[:, 0] - r), np.min(TANK_LENGTH - p[:, 0] - r),
                         np.min(p[:, 1] - r), np.min(TANK_WIDTH - p[:, 1] - r)])

    def breached(self, x: float, y: float, psi: float, vx: float = 0.0, vy: float = 0.0, age: float = 0.0) -> bool:
        """Whether the fish seen ``age`` s ago at ``(x, y, psi)`` moving at world velocity ``(vx, vy)`` must stop now.

        The fish may have moved on by ``v age`` since the pose, so that adds to the reaction distance.
        A non-finite pose or velocity counts as breached (stop rather than guess).
        """
        if not all(math.isfinite(v) for v in (x, y, psi, vx, vy, age)):
            return True
        toward = (-vx, vx, -vy, vy)
        react = self.reaction_time + max(age, 0.0)
        need = [self.margin + v * react + self.coast(v) for v in (max(t, 0.0) for t in toward)]
        return bool(np.any(self.clearance(x, y, psi) < np.array(need)))


def in_geofence(x: float, y: float, psi: float, body_length: float, margin: float) -> bool:
    """Whether the nose or the tail (``X +- L/2 cos psi``, ``Y +- L/2 sin psi``) is within ``margin`` of a wall.

    Nose and tail only, at rest: :class:`Geofence` is the rule the environment applies. A non-finite
    pose counts as outside (stop rather than guess).
    """
    if not all(math.isfinite(v) for v in (x, y, psi)):
        return True
    half = 0.5 * body_length
    for sign in (1.0, -1.0):
        px, py = x + sign * half * math.cos(psi), y + sign * half * math.sin(psi)
        if not (margin <= px <= TANK_LENGTH - margin and margin <= py <= TANK_WIDTH - margin):
            return True
    return False


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
