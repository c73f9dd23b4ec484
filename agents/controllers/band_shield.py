"""A safety filter for the hand law: keep the fish where it can still get out of the robot's stopping band.

The robot's geofence stops the fish once any part of its outline is closer to a wall than
``margin + v t_r + ln(max(v, v_c) / v_c) / k`` (:class:`pectoral_gym.agents.controllers.stop_band.StopBand`).
Being outside that band now is not enough: the fish's thrust cannot reverse within the env's ratio range
(eq. 25, ``(zeta^2 - 1) >= 0``) and its turning circle has a radius of ~0.25 m whatever the thrust (with
quadratic surge and yaw damping, eqs. 19-20, the steady radius does not depend on the force). Coasting
keeps it outside along one axis (the coast distance and the need shrink alike,
:mod:`pectoral_gym.model.tank`), which the rollouts below check on the planning model.

The filter is a backup shield (the "backup controller" form of a control barrier function): a set of
backup manoeuvres (coast with the fins still; turn left or right with one fin at a low level for
1 to 16 control periods, then coast) is known, and a command is allowed when, applied for one control
period and followed by some backup, the rollout on the planning model
(:func:`pectoral_gym.agents.controllers.fin_map.planning_spec`) stays out of the band, checked every
``check`` s, for ``horizon`` s. Otherwise the first interval of the best backup from now is applied:
a safe one if any (the turn to the side the law wanted first), else the one with the least shortfall.
If the nominal command was allowed at the last step, a backup from here is available at this one (in
the model), so the fish keeps an escape. The band is checked with ``extra_margin`` more clearance than
the robot's: the planning model's cycle-averaged velocity misses the full model's in-beat swing.

On the robot (``firmware``) the shield's fins, and the rollouts', follow the firmware's command path
(:class:`pectoral_gym.agents.controllers.firmware_path.FirmwarePath`: clipping, the rate rule where a fin
latches, stretched transitions) instead of latching every command as sent: the spin backups are made of
transitional strokes, whose latches the rules bound (``tests/test_firmware_path.py``).

Two options the NMPC turns on for the robot (``docs/notes/2026-12-04-nmpc-stops-2.md``): ``keep_side`` holds a
backup's kind and side from one intervention to the next while one of them is safe (the law's side flipped the
spin, restarting its transitional strokes), and ``reserve`` sends the nominal command only while several backups
remain after it (with one, the shield rode a single escape whose prediction was centimetres off).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from pectoral_gym.agents.controllers.fin_map import FinMap
from pectoral_gym.agents.controllers.firmware_path import FirmwarePath
from pectoral_gym.agents.controllers.stop_band import StopBand, band_violation
from pectoral_gym.agents.controllers.turning import SPIN_CYCLE, mirror
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.model.tank import ROBOT_STOP_RULE, StopRule, stop_need

__all__ = ["BACKUP_SPINS", "BACKUP_TURNS", "SLOWER", "BandShield", "band_speed", "through_firmware"]

BACKUP_TURNS = (4, 8, 16, 32)  # control periods a backup turns before it coasts
BACKUP_SPINS = (4, 8, 12, 20)  # control periods a backup spins (turning.SPIN_CYCLE) before it coasts
SPIN_PERIOD, SPIN_RATIO = 0.5, 5.0  # the fin-beat period [s] and ratio the spin cycle was found for
SLOWER = (1.0, 0.5)  # the law's amplitudes scaled by these (thrust ~ amplitude^2, eq. 25) before a backup
_COAST, _TURN, _SPIN = 0, 1, 2  # the kinds of backup (BandShield.kinds)


def through_firmware(config: EnvConfig, band: StopRule | None, firmware: bool | None) -> bool:
    """Whether a shield predicts through the robot firmware's command path (``BandShield``'s ``firmware``).

    ``firmware`` when given; else where ``band`` is given and the env ends no episode in a band of its own (the
    band is then the robot supervisor's).
    """
    return bool(firmware) if firmware is not None else band is not None and not config.stop_band


def band_speed(clearance: float, band: StopBand) -> float:
    """The largest speed [m/s] towards a wall at which ``clearance`` [m] is outside ``band`` (0 if none is).

    The need ``margin + v t_r + ln(max(v, v_c) / v_c) / k`` grows with ``v``; solved by bisection.
    """
    def need(v: float) -> float:
        return float(stop_need(v, band.k, band.rule))

    if need(0.0) >= clearance:
        return 0.0
    low, high = 0.0, 1.0
    if need(high) < clearance:
        return high
    for _ in range(40):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if need(mid) < clearance else (low, mid)
    return low


class BandShield:
    """Filters fin patterns so that a backup manoeuvre out of the stopping band always remains.

    Args:
        config: The environment settings.
        fins: The controller's fin map (period, ratio, amplitudes, planning model).
        band: The band's :class:`~pectoral_gym.model.tank.StopRule` (or its ``(margin, reaction_time,
            contact_speed)``); ``None``: the env's ``stop_rule`` where its
            ``stop_band`` is on (v1), else the robot's
            (:data:`~pectoral_gym.model.tank.ROBOT_STOP_RULE`).
        extra_margin: Clearance [m] added to the band's margin in the rollouts.
        horizon: Length of each rollout [s].
        check: Band check interval along the rollouts [s] (a divisor of the control period).
        turn_level: Thrust level (0..1, :meth:`FinMap.amplitude`) of the one fin a backup turn beats with.
        spin: Also back up with the on-the-spot spin (where the env's ranges, period and ratio allow it).
        speed_spread: Speed [m/s] added to the speed towards every wall, as the robot's geofence adds its
            velocity estimate's spread (``Geofence.breached``'s ``spread``).
        firmware: Predict the commands through the robot firmware's command path (:class:`FirmwarePath`).
            ``None``: where ``band`` is given and the env does not end episodes in a band of its own
            (``config.stop_band`` off): the band is then the robot supervisor's, as
            ``pectoral_gym.hardware.deploy.make_controller`` passes it.
        keep_side: Once a backup has been sent, keep to its kind (one-fin turn or spin) and side at the next
            intervention while one of them is safe, before the law's side: each flip of a spin restarts the
            firmware's transitional strokes, which drift the fish along its heading.
        reserve: Safe backups that must remain after the nominal command for it to be sent (1: one escape is
            enough); more makes the shield take over while it still has several ways out.
    """

    def __init__(self, config: EnvConfig, fins: FinMap, band: StopRule | None = None,
                 extra_margin: float = 0.02, horizon: float = 16.0, check: float = 0.5, turn_level: float = 0.06,
                 speed_spread: float = 0.0, spin: bool = True, firmware: bool | None = None,
                 keep_side: bool = False, reserve: int = 1):
        if int(reserve) < 1:
            raise ValueError(f"reserve must be >= 1 backup, got {reserve!r}")
        self.config = config
        self.keep_side, self.reserve = bool(keep_side), int(reserve)
        self.fins = fins
        firmware = through_firmware(config, band, firmware)
        band = (config.stop_rule if config.stop_band else ROBOT_STOP_RULE) if band is None else StopRule.coerce(band)
        self.band = StopBand.from_params(config.params, dataclasses.replace(band, margin=band.margin + extra_margin))
        self.speed_spread = float(speed_spread)
        self.dt = float(config.control_period)
        self.intervals = max(1, int(round(horizon / self.dt)))
        self.checks = max(1, int(round(self.dt / check)))
        rest = (fins.bias_mid, 0.0, fins.period, fins.ratio)
        one_fin = (fins.bias_mid, fins.amplitude(turn_level), fins.period, fins.ratio)
        self.rest = np.array([rest, rest])
        left, right = np.array([one_fin, rest]), np.array([rest, one_fin])  # the right fin alone turns left
        n = self.intervals
        plans, sides = [np.broadcast_to(self.rest, (n, 2, 4))], [0.0]
        for side, turn in ((1.0, left), (-1.0, right)):
            for m in BACKUP_TURNS:
                plans.append(np.array([turn if k < m else self.rest for k in range(n)]))
                sides.append(side)
        self.sides = np.array(sides)
        self.kinds = np.array([_COAST] + [_TURN] * (len(sides) - 1))
        self.backups = np.repeat(np.array(plans)[None], len(SPIN_CYCLE), axis=0)  # (spin phase, backups, n, 2, 4)
        low, high = config.amplitude_range
        b_low, b_high = config.bias_range
        self.spins = bool(spin and math.isclose(fins.period, SPIN_PERIOD) and math.isclose(fins.ratio, SPIN_RATIO)
                          and np.all((SPIN_CYCLE[:, :2] >= low) & (SPIN_CYCLE[:, :2] <= high))
                          and np.all((SPIN_CYCLE[:, 2:] >= b_low) & (SPIN_CYCLE[:, 2:] <= b_high)))
        if self.spins:  # on-the-spot turns: the cycle from each phase, left and right (mirrored)
            spin_plans = []
            for phase in range(len(SPIN_CYCLE)):
                rows = []
                for side in (1.0, -1.0):
                    for m in BACKUP_SPINS:
                        plan = np.array(np.broadcast_to(self.rest, (n, 2, 4)))
                        for k in range(min(m, n)):
                            u = SPIN_CYCLE[(phase + k) % len(SPIN_CYCLE)]
                            u = u if side > 0 else mirror(u)  # amplitude R/L, bias R/L
                            plan[k, :, 0], plan[k, :, 1] = u[2:], u[:2]
                        rows.append(plan)
                spin_plans.append(rows)
            self.backups = np.concatenate([self.backups, np.array(spin_plans)], axis=1)
            self.sides = np.concatenate([self.sides, np.repeat([1.0, -1.0], len(BACKUP_SPINS))])
            self.kinds = np.concatenate([self.kinds, np.full(2 * len(BACKUP_SPINS), _SPIN)])
        self._shadow = fins.spec.build(1, config.params, k=fins.scaling)
        self._path = FirmwarePath(1) if firmware else None  # the shadow's firmware setpoint
        self._batch = self._batch_path = None
        self.interventions = self.slowed = self._phase = 0
        self._held: int | None = None  # the backup sent at the last step (its index), None after a nominal command

    def reset(self) -> None:
        """Start of an episode: the shadow fins at rest at the start of a power stroke, as the envs reset them."""
        self._shadow.reset()
        if self._path is not None:
            self._path.reset()
        self.interventions = self.slowed = self._phase = 0
        self._held = None

    @property
    def firmware(self) -> bool:
        """Whether the commands are predicted through the robot firmware's command path."""
        return self._path is not None

    def applied(self, patterns: np.ndarray) -> None:
        """Follow the patterns ``(2, 4)`` the controller sent, for one control period."""
        self._advance(self._shadow, self._path, self._latched(patterns)[None], self.dt)
        self._phase = (self._phase + 1) % len(SPIN_CYCLE)

    def spin_patterns(self, side: float) -> np.ndarray:
        """Patterns ``(2, 4)`` of the spin cycle's row for the current phase (``side`` > 0 left, < 0 right)."""
        u = SPIN_CYCLE[self._phase]
        u = u if side > 0 else mirror(u)  # amplitude R/L, bias R/L
        f = self.fins
        return np.array([[u[2], u[0], f.period, f.ratio], [u[3], u[1], f.period, f.ratio]])

    def _latched(self, patterns: np.ndarray) -> np.ndarray:
        """What the env latches for ``patterns`` ``(..., 2, 4)``: clipped to its ranges."""
        return self.config.decode(self.config.encode(np.asarray(patterns, dtype=np.float64)))

    def shortfalls(self, state: np.ndarray, firsts: np.ndarray) -> np.ndarray:
        """Band shortfall [m^2] summed along each rollout: each of ``firsts`` then each backup; each backup from now.

        Args:
            state: Body state ``(X, Y, psi, vx, vy, omega)`` (the fins are the shadow's).
            firsts: Patterns ``(F, 2, 4)`` for the first control period.

        Returns:
            ``(F + 1, backups)``: row ``i < F`` after ``firsts[i]``, the last row from now.
        """
        backups = self.backups[self._phase]
        nb, nf = len(backups), len(firsts)
        if self._batch is None or self._batch.n != (nf + 1) * nb:
            self._batch = self.fins.spec.build((nf + 1) * nb, self.config.params, k=self.fins.scaling)
            self._batch_path = None if self._path is None else FirmwarePath(self._batch.n)
        b, path = self._batch, self._batch_path
        plans = np.tile(backups, (nf + 1, 1, 1, 1))
        plans[:nf * nb, 0] = np.repeat(firsts, nb, axis=0)
        plans = self._latched(plans)
        b.state[:] = state
        b.fins[:] = self._shadow.fins[0]
        b.pending[:] = self._shadow.pending[0]
        b.forcing_cache[:] = self._shadow.forcing_cache[0]
        if path is not None:
            path.copy_from(self._path)
        total = np.zeros(b.n)
        h = self.dt / self.checks
        for k in range(self.intervals):
            for c in range(self.checks):
                total += self._violation(self._advance(b, path, plans[:, k] if c == 0 else None, h), self.band)
        return total.reshape(nf + 1, nb)

    @staticmethod
    def _advance(model, path: FirmwarePath | None, patterns: np.ndarray | None, duration: float) -> np.ndarray:
        """Command ``patterns`` ``(n, 2, 4)`` (``None``: none new) and advance ``model``, through ``path`` if any."""
        if path is None:
            if patterns is not None:
                model.command_array(patterns, validate=False)
            return model.advance(duration)
        if patterns is not None:
            path.command(patterns)
        return path.advance(model, duration)

    def _violation(self, s: np.ndarray, band: StopBand) -> np.ndarray:
        """:func:`band_violation` of states ``(n, 6)``, with :attr:`speed_spread` towards every wall.

        The world velocity shifted by ``(+w, +w)`` adds ``w`` towards the walls ``X = L`` and ``Y = W``, by
        ``(-w, -w)`` towards ``X = 0`` and ``Y = 0``: the sum of the two is zero exactly when every wall is
        clear with the spread (as ``Geofence.breached`` adds it).
        """
        w = self.speed_spread
        if w == 0.0:
            return band_violation(s[:, 0], s[:, 1], s[:, 2], s[:, 3], s[:, 4], band, np)
        c, si = np.cos(s[:, 2]), np.sin(s[:, 2])
        total = 0.0
        for sign in (1.0, -1.0):  # body-frame velocity of the world shift (sign w, sign w)
            dx, dy = sign * w * (c + si), sign * w * (c - si)
            total = total + band_violation(s[:, 0], s[:, 1], s[:, 2], s[:, 3] + dx, s[:, 4] + dy, band, np)
        return total

    def filter(self, state: np.ndarray, nominal: np.ndarray, side: float) -> np.ndarray:
        """The patterns ``(2, 4)`` to send: ``nominal``, or slowed (:data:`SLOWER`), if a backup remains after it.

        Otherwise the first interval of the best backup from now.

        Args:
            state: Body state ``(6,)`` estimated from the observation.
            nominal: The law's patterns ``(2, 4)``.
            side: The turn the law wants (> 0 left, < 0 right): the backup turning that way wins ties.
        """
        nominal = np.asarray(nominal, dtype=np.float64)
        firsts = np.repeat(nominal[None], len(SLOWER), axis=0)
        firsts[:, :, 1] *= np.asarray(SLOWER)[:, None]
        rows = self.shortfalls(np.asarray(state, dtype=np.float64), firsts)
        for i in range(len(SLOWER)):
            if np.count_nonzero(rows[i] <= 0.0) >= self.reserve:
                if i > 0:
                    self.slowed += 1
                self._held = None
                return firsts[i]
        now = rows[-1]
        self.interventions += 1
        safe = now <= 0.0
        n = len(self.sides)
        # a turn to the law's side first, then the shortest turn (the coast counts as the shortest)
        preference = np.where(self.sides * side > 0, 0, 1) * n + np.arange(n)
        if self.keep_side and self._held is not None:  # before those: the manoeuvre under way, same kind and side
            held = (self.kinds == self.kinds[self._held]) & (self.sides == self.sides[self._held])
            preference = np.where(held, 0, 2 * n) + preference
        if np.any(safe):
            best = int(np.argmin(np.where(safe, preference, np.iinfo(np.int64).max)))
        else:
            best = int(np.argmin(now))
        self._held = best
        return self.backups[self._phase, best, 0].copy()
