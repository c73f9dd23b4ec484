"""PC-side safety rules of the hardware environment (the robot's own: :mod:`~pectoral_gym.hardware.firmware`).

* :func:`check_action`: a non-finite action is rejected before anything is sent.
* :class:`CommandFilter`: commands clipped to the servo limits and rate-limited per control step.
* :class:`Geofence`: any part of the fish (body and fin tips) closer to a wall than it needs to stop
  (reaction distance plus the coasting distance of eq. (19) with the fins still) -> stop, end the episode;
  :func:`in_geofence` is the older nose-and-tail test.
* :class:`SpeedBound`: the fastest the fish can be moving, from what its fins can do since the reset
  (``docs/hardware.md``, "Physical speed bound"); the geofence never uses a speed above it, and assumes it
  grows while the fish is unseen.
* :class:`TrackingWatch`: tracking lost for longer than ``timeout`` -> stop, end the episode.
* :func:`install_stop_handlers`: Ctrl-C and SIGTERM send stop before the program ends.

:class:`pectoral_gym.hardware.supervisor.Supervisor` applies these rules in its own thread, also between steps;
:class:`pectoral_gym.hardware.framecheck.FrameCheck` decides which camera frames count as a sighting.
"""

from __future__ import annotations

import math
import signal
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from pectoral_gym.hardware.firmware import ServoLimits, clip_beats, rate_limit, stretch_transition
from pectoral_gym.hardware.protocol import DEFAULT_LEASE, MAX_LEASE
from pectoral_gym.model import tank
from pectoral_gym.model.params import FishParams, body_coefficients

__all__ = ["SafetyConfig", "check_action", "CommandFilter", "Geofence", "SpeedBound", "in_geofence", "TrackingWatch",
           "install_stop_handlers"]


@dataclass(frozen=True)
class SafetyConfig:
    """PC-side safety settings.

    Attributes:
        limits: Servo limits (clipping and rate limiting), shared with the firmware rules.
        geofence_margin: Clearance kept from every wall on top of the stopping distance [m].
        tracking_timeout: Stop when the fish has not been seen for this long [s]; in ``(0, coast_horizon]``
            (while the fish is unseen the geofence assumes the worst motion the fins allow, and its guarantee
            lasts ``coast_horizon`` after a stop).
        link_timeout: Stop when the robot has not answered for this long [s].
        lease: Lease of each command from ``step()`` [s]: the robot stops this long after it receives a
            command unless a new one comes (``docs/protocol.md``); at most ``protocol.MAX_LEASE``.
        step_slack: Time allowed between the end of one ``step()`` and the start of the next (policy
            compute time, timing jitter) [s]; ``step()`` renews the lease only while it runs, to last
            this long past its own end.
        coast_horizon: The geofence keeps the fish off the walls for this long after a stop [s].
        reaction_time: Time from a pose to the fins halting (frame age, polling, radio) [s].
        max_frame_lead: Camera timestamps further ahead of this machine's clock are rejected [s].
        pose_noise: Standard deviation of the tracked position assumed for the geofence's speed estimate [m]
            (the fit's own scatter is used when larger).
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
    pose_noise: float = 0.005

    def __post_init__(self) -> None:
        for name in ("geofence_margin", "tracking_timeout", "link_timeout", "lease", "step_slack", "coast_horizon",
                     "reaction_time", "max_frame_lead", "pose_noise"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"SafetyConfig.{name} must be a finite number >= 0, got {value!r}")
        if self.tracking_timeout <= 0:
            raise ValueError(f"SafetyConfig.tracking_timeout must be > 0 s, got {self.tracking_timeout!r}")
        if self.tracking_timeout > self.coast_horizon:
            raise ValueError(f"SafetyConfig.tracking_timeout = {self.tracking_timeout} s exceeds the physical bound "
                             f"coast_horizon = {self.coast_horizon} s (the geofence keeps a blind fish clear only "
                             "that long after a stop)")
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

    Mirrors the firmware: the peak rate of every half-stroke (:func:`pectoral_gym.hardware.firmware.clip_beats`) and of
    the transitional half-stroke into the new pattern from either turning point of the previous command
    (:func:`pectoral_gym.hardware.firmware.stretch_transition`) stays within ``limits.max_speed``.

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
        self.params = params
        self.k = tank.coast_rate(body_coefficients(params))  # [1/m]
        self.shape = tank.Outline.from_params(params)
        self.half_length, self.width, self.span = self.shape
        self.margin, self.reaction_time, self.horizon = float(margin), float(reaction_time), float(horizon)

    def coast(self, speed: float) -> float:
        """Distance [m] covered in ``horizon`` s by a fish coasting from ``speed`` [m/s] with its fins still."""
        return float(tank.coast_distance(float(speed), self.k, self.horizon))

    def outline(self, x: float, y: float, psi: float) -> tuple[np.ndarray, np.ndarray]:
        """Centres ``(4, 2)`` (nose, tail, right and left fin pivot) and radii ``(4,)`` of the outline [m]."""
        return tank.outline_arrays(x, y, psi, self.shape)

    def clearance(self, x: float, y: float, psi: float) -> np.ndarray:
        """Distance [m] from the outline to the walls ``X = 0, X = L, Y = 0, Y = W`` (negative: across)."""
        return tank.clearance(x, y, psi, self.shape)

    def breached(self, x: float, y: float, psi: float, vx: float = 0.0, vy: float = 0.0, age: float = 0.0,
                 spread: tuple[float, float] = (0.0, 0.0), bound: float = math.inf, gain: float = 0.0) -> bool:
        """Whether the fish seen ``age`` s ago at ``(x, y, psi)`` moving at world velocity ``(vx, vy)`` must stop now.

        The speed towards each wall is the measured one plus its uncertainty ``spread`` ``(sX, sY)`` [m/s],
        plus ``gain`` [m/s] (the most it can have gained while unseen), never above ``bound`` [m/s] (the
        physical bound, :class:`SpeedBound`) and never below 0. That speed, held from the pose until the
        fins halt (``age + reaction_time``), adds to the coasting distance. A non-finite pose or velocity
        counts as breached (stop rather than guess).
        """
        values = (x, y, psi, vx, vy, age, *spread, gain)
        if not all(math.isfinite(v) for v in values) or math.isnan(bound):
            return True
        sx, sy = (max(float(s), 0.0) for s in spread)
        toward = (-vx + sx, vx + sx, -vy + sy, vy + sy)
        react = self.reaction_time + max(age, 0.0)
        speeds = (min(max(t, 0.0) + max(gain, 0.0), bound) for t in toward)
        need = [self.margin + v * react + self.coast(v) for v in speeds]
        return bool(np.any(self.clearance(x, y, psi) < np.array(need)))


class _Riccati(NamedTuple):
    """``du/dt <= gain - kappa u^2`` while the fins may run, ``<= -kappa u^2`` while still; ``|V| <= u / scale``."""

    gain: float
    kappa: float
    scale: float

    @property
    def top(self) -> float:
        return math.sqrt(self.gain / self.kappa)

    def advance(self, u: float, run: float, coast: float) -> float:
        """``u`` after ``run`` s with the fins possibly running, then ``coast`` s with them still (closed form)."""
        top = self.top
        if run > 0:
            r = math.sqrt(self.gain * self.kappa)
            if u < top:  # from below the fixed point
                u = top * math.tanh(r * run + math.atanh(u / top))
            elif u > top:
                u = top / math.tanh(r * run + 0.5 * math.log((u + top) / (u - top)))
        if coast > 0:
            u = u / (1.0 + self.kappa * u * coast)
        return u


class SpeedBound:
    """The fastest the fish can move, ``|V| <= bound(t)``, from the times its fins may have run since a reset.

    Two rigorous bounds of eqs. (19)-(20), each integrated in closed form; the smaller rules (derivations in
    ``docs/hardware.md``, "Physical speed bound"):

    * impulse: Kirchhoff's linear impulse ``P = R(psi) (m1 vx, m2 vy)`` obeys ``dP/dt = R(psi) (f + h)`` (the
      Munk terms are the rotation of the body frame; ``f`` the fins' force, ``h`` the drag and lift of
      (20)), so ``d|P|/dt <= F - kappa_P |P|^2`` and ``|V| <= |P| / min(m1, m2)``: the tighter while the fins
      run (``F``: the most two fins can push);
    * energy: ``E = (m1 vx^2 + m2 vy^2 + J3 omega^2) / 2`` gives ``du/dt <= G - kappa_E u^2`` with ``u =
      sqrt(2 E)`` and ``|V| <= u / sqrt(min(m1, m2))``: the tighter while the fish coasts.

    The fin force is the largest the servo limits allow (peak rate ``max_speed``, shortest half-stroke,
    eqs. (13)-(17)).

    Args:
        params: Fish parameters.
        limits: Servo limits the firmware enforces.

    Attributes:
        top: The bound's limit with the fins running for ever [m/s]. accel: Its fastest growth [m/s^2].
    """

    def __init__(self, params: FishParams, limits: ServoLimits):
        coef = body_coefficients(params)
        w = limits.max_speed
        d_min = limits.period_min * min(limits.ratio_min / (limits.ratio_min + 1.0), 1.0 / (limits.ratio_max + 1.0))
        # One fin: |F_n| = k g'^2 (13) plus the fin's inertia m_p |a(S_p / 2)| = I_p sqrt(g''^2 + g'^4) (15),
        # with |g''| <= pi |g'|_peak / d for a half-cosine stroke of duration d.
        force = params.fin_drag_constant * w * w + params.fin_inertia_constant * math.hypot(w * w, math.pi * w / d_min)
        m_min, m_max = min(coef.m1, coef.m2), max(coef.m1, coef.m2)
        # Impulse: p . h <= -c1 |V| (m1 vx^2 + m2 vy^2) + c2 |alpha| |m1 - m2| |vx vy| |V|, with |alpha| <= pi/2,
        # |vx vy| <= |V|^2 / 2, |p| / m_max <= |V| <= |p| / m_min.
        leak = coef.c2 * (math.pi / 4.0) * abs(coef.m1 - coef.m2) / m_min ** 3
        kappa_p = coef.c1 / m_max ** 2 - leak
        if kappa_p <= 0:
            raise ValueError(f"SpeedBound: drag does not dominate lift for these parameters (c1 / max(m1, m2)^2 = "
                             f"{coef.c1 / m_max ** 2:.4g} <= {leak:.4g})")
        self._impulse = _Riccati(2.0 * force, kappa_p, m_min)  # |f_R + f_L| <= |f_R| + |f_L|
        # Energy: G bounds sqrt(Fx^2 / m1 + Fy^2 / m2 + tau^2 / J3), tau = C_p (fx_R - fx_L); the dissipation
        # c1 |V|^3 + C_M |omega|^3 is at least kappa u^3 on the ellipse E = u^2 / 2.
        alpha = coef.c1 / m_max ** 1.5
        beta = params.moment_coef / coef.J3 ** 1.5
        gain_e = 2.0 * force * math.sqrt(1.0 / m_min + params.fin_offset ** 2 / coef.J3)
        self._energy = _Riccati(gain_e, alpha * beta / math.hypot(alpha, beta), math.sqrt(m_min))
        self._bounds = (self._impulse, self._energy)
        self.top = min(b.top / b.scale for b in self._bounds)
        self.accel = min(b.gain / b.scale for b in self._bounds)
        self.reset(0.0)

    def reset(self, t: float) -> None:
        """The fish is at rest at ``t`` [s] with its fins still (placed after a confirmed stop)."""
        self._t, self._u, self.run_until = float(t), (0.0, 0.0), -math.inf

    def unknown(self, t: float) -> None:
        """Nothing is known at ``t`` [s] (a fresh start): the bounds' top values, fins possibly running until ``t``.

        Any history that began at rest keeps each bound at or below its top value, so this is an upper bound.
        """
        self._t, self._u, self.run_until = float(t), tuple(b.top for b in self._bounds), float(t)

    def stopped(self, t: float) -> None:
        """The robot confirmed its fins still at ``t`` [s] (no command sent since)."""
        self._u, self._t = self._state(t), float(t)
        self.run_until = min(self.run_until, float(t))

    def running(self, t: float, until: float) -> None:
        """The fins may run from ``t`` to ``until`` [s] (a command sent at ``t`` with its lease)."""
        self._u, self._t = self._state(t), float(t)
        self.run_until = max(self.run_until, float(until))

    def _state(self, t: float) -> tuple[float, ...]:
        if t <= self._t:
            return self._u
        run = max(min(t, self.run_until) - self._t, 0.0)
        coast = t - self._t - run
        return tuple(b.advance(u, run, coast) for b, u in zip(self._bounds, self._u, strict=True))

    def __call__(self, t: float) -> float:
        """The bound on ``|V|`` [m/s] at time ``t`` (not before the last :meth:`running` or :meth:`reset`)."""
        return min(u / b.scale for b, u in zip(self._bounds, self._state(t), strict=True))

    def peak(self, t0: float, t1: float) -> float:
        """The largest bound over ``[t0, t1]`` (each rises while the fins may run and falls after)."""
        times = [t for t in (t0, t1, self.run_until) if t0 <= t <= t1]
        return max(self(max(t, self._t)) for t in times)

    def may_run(self, t: float) -> bool:
        """Whether the fins may be running at ``t``."""
        return t <= self.run_until


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
        if min(tank.wall_gaps(px, py)) < margin:
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
