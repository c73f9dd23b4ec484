"""Where the fish may be: the geofence and the physical speed bound it relies on.

* :class:`Geofence`: any part of the fish (body and fin tips) closer to a wall than it needs to stop
  (reaction distance plus the coasting distance of eq. (19) with the fins still) -> stop, end the episode;
  :func:`in_geofence` is the older nose-and-tail test.
* :class:`SpeedBound`: the fastest the fish can be moving, from what its fins can do since the reset
  (``docs/guide/safety.md``, "Physical speed bound"); the geofence never uses a speed above it, and assumes it
  grows while the fish is unseen.

The other PC-side rules are :mod:`pectoral_gym.hardware.safety.rules`'s; the robot's own are
:mod:`~pectoral_gym.hardware.radio.firmware`'s.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from pectoral_gym.hardware.safety.blind import fin_pair_force_bound
from pectoral_gym.model import tank
from pectoral_gym.model.params import FishParams, body_coefficients
from pectoral_gym.model.servo import ServoLimits

__all__ = ["Geofence", "SpeedBound", "in_geofence"]


class Geofence:
    """Whether the fish can still stop before any part of it reaches a wall.

    The outline is a capsule from nose to tail of radius ``C_p`` (the body width) and a disc of radius
    ``S_p`` around each fin pivot ``(0, +-C_p)`` (the fin tip wherever the fin points). Per wall, the
    clearance of the outline must exceed ``margin + v t_r + d_coast(v)`` with ``v`` the speed towards
    that wall, ``t_r`` the reaction time and the coasting distance with the fins still down to the contact
    speed ``v_c``: eq. (19) with no fin force and the motion along one axis is ``m dv/dt = -c1 v |v|``, so
    ``v(x) = v0 exp(-k x)`` and ``d_coast = ln(max(v0, v_c) / v_c) / k`` with ``k = c1 / m``
    (``docs/model.md``, body coefficients), ``m`` the larger of ``m1, m2`` (the slower decay). Yaw coupling
    is neglected; ``margin`` covers it.

    Args:
        params: Fish geometry and body coefficients.
        rule: The band's :class:`~pectoral_gym.model.tank.StopRule` (margin [m], ``t_r`` [s], ``v_c`` [m/s]; the
            envs' ``stop_rule`` of the same name; ``SafetyConfig.stop_rule`` on the robot).

    Attributes:
        rule: The rule.
        k: :func:`~pectoral_gym.model.tank.coast_rate` of ``params`` [1/m].
        shape: The fish's :class:`~pectoral_gym.model.tank.Outline`.
    """

    def __init__(self, params: FishParams, rule: tank.StopRule):
        if not isinstance(rule, tank.StopRule):
            raise TypeError(f"Geofence needs a pectoral_gym.model.tank.StopRule, got {rule!r}")
        self.params = params
        self.rule = rule
        self.k = tank.coast_rate(body_coefficients(params))  # [1/m]
        self.shape = tank.Outline.from_params(params)
        self.half_length, self.width, self.span = self.shape
        self.breached(0.5 * tank.TANK_LENGTH, 0.5 * tank.TANK_WIDTH, 0.0)  # compile or load the kernel now

    def coast(self, speed: float) -> float:
        """Distance [m] a fish coasting from ``speed`` [m/s] with its fins still covers until it is down to ``v_c``."""
        return float(tank.coast_distance(float(speed), self.k, self.rule.contact_speed))

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
        rule = self.rule
        react = rule.reaction_time + max(age, 0.0)
        speeds = tuple(min(max(t, 0.0) + max(gain, 0.0), bound) for t in toward)
        c, s = math.cos(psi), math.sin(psi)
        shortfall = tank.band_shortfall(x, y, c, s, speeds, self.shape, self.k, rule.margin, react, rule.contact_speed)
        return bool(shortfall > 0)


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
    ``docs/guide/safety.md``, "Physical speed bound"):

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
        # Each fin: |F_n| = s k g'^2 (13) plus the fin's inertia m_p |a(S_p / 2)| = I_p sqrt(g''^2 + g'^4) (15),
        # at the servos' peak rate and shortest half-stroke, each fin with its own force factor and servo scale.
        pair = fin_pair_force_bound(params, limits)
        m_min, m_max = min(coef.m1, coef.m2), max(coef.m1, coef.m2)
        # Impulse: p . h <= -c1 |V| (m1 vx^2 + m2 vy^2) + c2 |alpha| |m1 - m2| |vx vy| |V|, with |alpha| <= pi/2,
        # |vx vy| <= |V|^2 / 2, |p| / m_max <= |V| <= |p| / m_min.
        leak = coef.c2 * (math.pi / 4.0) * abs(coef.m1 - coef.m2) / m_min ** 3
        kappa_p = coef.c1 / m_max ** 2 - leak
        if kappa_p <= 0:
            raise ValueError(f"SpeedBound: drag does not dominate lift for these parameters (c1 / max(m1, m2)^2 = "
                             f"{coef.c1 / m_max ** 2:.4g} <= {leak:.4g})")
        self._impulse = _Riccati(pair, kappa_p, m_min)  # |f_R + f_L| <= |f_R| + |f_L|
        # Energy: G bounds sqrt(Fx^2 / m1 + Fy^2 / m2 + tau^2 / J3), tau = C_p (fx_R - fx_L); the dissipation
        # c1 |V|^3 + C_M |omega|^3 is at least kappa u^3 on the ellipse E = u^2 / 2.
        alpha = coef.c1 / m_max ** 1.5
        beta = params.moment_coef / coef.J3 ** 1.5
        gain_e = pair * math.sqrt(1.0 / m_min + params.fin_offset ** 2 / coef.J3)
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
