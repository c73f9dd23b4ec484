"""The hand-designed feedback controller (a baseline, and the NMPC's base policy).

Physics used by the hand controller (``docs/model.md``):

* a fin's averaged thrust is ``k pi^2 (zeta^2 - 1) / (zeta T_p^2) gA J1(gA) sin(g0)``:
  it grows with the amplitude ``gA``, the ratio ``zeta`` and ``1 / T_p``;
  the controllers fix ``T_p`` at the shortest and ``zeta`` at the largest value of
  the env's ranges (most thrust per amplitude, shortest wait until a fin latches
  a new pattern) and steer with the amplitudes and biases;
* the right fin pushes on the right side of the body: alone, it turns the fish
  **left** (``omega > 0``); the left fin turns it right;
* a bias ``g0 < 90 deg`` on the right fin (``> 90 deg`` on the left fin) adds a
  lateral force to the left (``f_hy ~ cos g0``, eq. 25).
"""

from __future__ import annotations

import math
import os

import numpy as np

from pectoral_gym.agents.controllers.band_shield import BandShield, band_speed
from pectoral_gym.agents.controllers.fin_map import FinMap, planning_spec
from pectoral_gym.agents.controllers.turning import circle_room, inside_turning_circle
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.envs.observation import Observation, decode, one_observation
from pectoral_gym.model import tank

__all__ = ["HandController"]

_MORE_ROOM = 0.05  # m: the hand law turns the long way round only for this much more room (no flip-flop on ties)


class HandController:
    """Feedback from heading and distance errors to differential fin amplitude and bias.

    With ``e`` the bearing of the aim point in the body frame (> 0: to the left)
    and ``d`` its distance:

    * turn command ``u = turn_level clip(heading_gain e - rate_gain omega, -1, 1)``, ``omega`` the mean yaw rate over
      the last control period from the change of heading (the full model's instantaneous yaw rate
      swings within each fin beat, and sampling it once per period aliases); the right fin gets
      thrust level ``s + u``, the left ``s - u`` (right fin stronger turns left);
    * forward thrust level ``s`` from the desired speed ``v = min(speed_gain d, max) max(cos e, 0)^p``
      through the drag balance; ``track`` adds the reference speed (feed-forward) and aims
      ``lookahead`` seconds ahead of the moving reference point;
    * differential bias ``g0 = 90 deg -+ bias_gain e`` (right, left) adds a lateral force towards the aim;
    * walls: a turn of radius ``turn_radius`` towards an aim behind the fish (``|e| > 90 deg``) whose
      turning circle leaves less than ``wall_margin`` to a wall turns the other way when that circle has
      5 cm more room; an aim inside the turning circle (unreachable by turning) makes the fish swim straight
      on at ``escape_speed`` (or, with a wall closer than ``turn_radius + wall_margin`` ahead, turn
      towards the roomier side) until it is not. The fish never stalls there: with ``alignment`` ~ 0
      and no turn it would stay put for the whole episode.

    Args:
        config: The environment settings.
        heading_gain: Turn command per radian of bearing [1/rad].
        rate_gain: Turn command per rad/s of yaw rate (damping) [s/rad].
        speed_gain: Desired speed per metre of distance [1/s].
        bias_gain: Bias offset per radian of bearing [-]. Off by default: on the full model it lowered the
            goal success (the lateral force is small).
        bias_max: Largest bias offset from 90 deg [rad].
        lookahead: ``track``: aim this far ahead of the reference point along its velocity [s].
        turn_level: Largest differential thrust level. Small: the full model turns tightest at small
            amplitudes (turning radius ~0.25 m at 10-15 deg, ~0.5 m at 30 deg with one fin).
        turn_radius: Turning radius assumed by the reachability and wall rules [m].
        alignment_power: Forward speed falls as ``max(cos e, 0)^alignment_power`` off the aim.
        wall_margin: Room [m] a turning circle (or the path ahead) must leave to the walls, beyond half
            the body length.
        escape_speed: Speed [m/s] of the straight run that takes an aim out of the turning circle.
        shield: Filter the commands through a :class:`~pectoral_gym.agents.controllers.band_shield.BandShield`
            (``True``, or a dict of its arguments): the fish keeps out of the robot's stopping band and
            slows towards a goal near a wall so that it arrives outside it (:meth:`_arrival_cap`).
        spin: With the shield, ``goal``: an aim inside the turning circle is turned to on the spot
            (:data:`pectoral_gym.agents.controllers.turning.SPIN_CYCLE`) instead of swimming on.
        scaling: The K file of the planning model (:func:`~pectoral_gym.agents.controllers.fin_map.planning_spec`):
            a robot's own K where ``config.params`` are not Table 1's; ``None``: the env's (the shipped K).
    """

    name = "hand"

    def __init__(self, config: EnvConfig, heading_gain: float = 1.5, rate_gain: float = 1.0,
                 speed_gain: float = 0.3, bias_gain: float = 0.0, bias_max: float = math.radians(15.0),
                 lookahead: float = 2.0, turn_level: float = 0.12, turn_radius: float = 0.25,
                 alignment_power: float = 8.0, wall_margin: float = 0.15, escape_speed: float = 0.05,
                 shield: bool | dict = True, spin: bool = True, scaling: str | os.PathLike | None = None):
        self.config = config
        self.fins = FinMap(config, planning_spec(config, scaling))
        self.heading_gain = float(heading_gain)
        self.rate_gain = float(rate_gain)
        self.speed_gain = float(speed_gain)
        self.bias_gain = float(bias_gain)
        self.bias_max = float(bias_max)
        self.lookahead = float(lookahead)
        self.turn_level = float(turn_level)
        self.turn_radius = float(turn_radius)
        self.alignment_power = float(alignment_power)
        self.wall_margin = float(wall_margin)
        self.escape_speed = float(escape_speed)
        self.half_length = 0.5 * config.params.body_length
        self.track = config.task == "track"
        self._heading: float | None = None
        self.shield = None
        self.spin = bool(spin)
        if shield:
            self.shield = BandShield(config, self.fins, **(shield if isinstance(shield, dict) else {}))

    def reset(self, seed: int | None = None) -> None:
        """Forget the previous heading (start of an episode)."""
        self._heading = None
        if self.shield is not None:
            self.shield.reset()

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Action for one observation ``(19,)``."""
        obs = one_observation(obs)  # the fin block (observe_fins), if any, is not read
        o = decode(obs)
        heading = math.atan2(o.sin_psi, o.cos_psi)
        rate = 0.0 if self._heading is None else _wrap(heading - self._heading) / self.config.control_period
        self._heading = heading
        b_r, a_r, b_l, a_l = self.command(o, rate)
        if self.shield is None:
            return self.fins.action(b_r, a_r, b_l, a_l)
        f = self.fins
        nominal = np.array([[b_r, a_r, f.period, f.ratio], [b_l, a_l, f.period, f.ratio]])
        side = a_r - a_l  # > 0: the law turns left (the right fin rows harder)
        bearing = math.atan2(o.target_y, o.target_x)
        if (self.spin and not self.track and self.shield.spins
                and inside_turning_circle(math.hypot(o.target_x, o.target_y), bearing, self.turn_radius)):
            side = 1.0 if bearing > 0 else -1.0
            nominal = self.shield.spin_patterns(side)  # turn on the spot to the goal
        state = np.array([o.x, o.y, heading, o.vx, o.vy, o.omega])
        patterns = self.shield.filter(state, nominal, side)
        self.shield.applied(patterns)
        return f.action(patterns[0, 0], patterns[0, 1], patterns[1, 0], patterns[1, 1])

    def command(self, o: Observation, rate: float) -> tuple[float, float, float, float]:
        """The law's fin patterns for one observation and yaw rate (no state is kept).

        Args:
            o: The observation (:func:`pectoral_gym.envs.observation.decode`), or one built from a
                predicted state (the NMPC screens the law's closed-loop rollout on its model).
            rate: Yaw rate [rad/s] (``act`` passes the mean over the last control period).

        Returns:
            ``(bias_right, amplitude_right, bias_left, amplitude_left)`` [rad] (period and ratio: :class:`FinMap`'s).
        """
        aim_x, aim_y = o.target_x, o.target_y
        ref_speed = 0.0
        if self.track:  # feed forward: aim ahead of the moving reference and add its speed
            aim_x += self.lookahead * o.target_vx
            aim_y += self.lookahead * o.target_vy
            ref_speed = math.hypot(o.target_vx, o.target_vy)
        distance = math.hypot(aim_x, aim_y)
        bearing = math.atan2(aim_y, aim_x)
        turn = float(np.clip(self.heading_gain * bearing - self.rate_gain * rate, -1.0, 1.0))
        alignment = max(math.cos(bearing), 0.0) ** self.alignment_power
        speed = (min(self.speed_gain * distance, self.fins.max_speed) + ref_speed) * alignment
        if self.shield is not None and not self.track:
            cap = self._arrival_cap(o, aim_x, aim_y, distance)
            speed = 0.0 if o.vx > cap else min(speed, cap)  # faster than the cap: coast (thrust cannot brake)
        if inside_turning_circle(distance, bearing, self.turn_radius):
            # the aim lies inside the turning circle: swim on until a turn can reach it
            turn = 0.0
            if not self.track:  # a moving reference comes out of the circle by itself
                speed = max(speed, self.escape_speed)
            if self._room_ahead(o) < self.turn_radius + self.wall_margin:
                turn = 1.0 if self._room(o, 1.0) >= self._room(o, -1.0) else -1.0
        elif abs(bearing) > 0.5 * math.pi:
            side = 1.0 if bearing > 0 else -1.0  # turn left for an aim on the left
            if self._room(o, side) < self.wall_margin and self._room(o, -side) > self._room(o, side) + _MORE_ROOM:
                turn = -side  # the long way round: the short turn would run into a wall
        level = self.fins.level_for_speed(speed)
        offset = float(np.clip(self.bias_gain * bearing, -self.bias_max, self.bias_max))
        low, high = self.config.bias_range
        f = self.fins
        return (float(np.clip(f.bias_mid - offset, low, high)), f.amplitude(level + self.turn_level * turn),
                float(np.clip(f.bias_mid + offset, low, high)), f.amplitude(level - self.turn_level * turn))


    def _arrival_cap(self, o: Observation, aim_x: float, aim_y: float, distance: float) -> float:
        """Speed [m/s] from which coasting reaches the goal radius no faster than the band allows there.

        Coasting with the fins still, eq. (19) along one axis, ``dv/dx = -k v``: the speed falls by
        ``exp(-k x)`` over ``x`` m, so the cap is the band's speed where the fish reaches the goal radius
        (:func:`band_speed` for that point's clearance to the nearest wall less the nose: half the body and
        ``C_p``) times ``exp(k (distance - goal_radius))``.
        """
        radius = self.config.goal_radius
        room = max(distance - radius, 0.0)
        reach = room / distance if distance > 0 else 0.0  # the arrival point, on the line to the goal
        c, s = o.cos_psi, o.sin_psi
        gx, gy = o.x + reach * (c * aim_x - s * aim_y), o.y + reach * (s * aim_x + c * aim_y)
        band = self.shield.band
        clearance = min(tank.wall_gaps(gx, gy)) - band.outline.half_length - band.outline.width
        return band_speed(clearance, band) * math.exp(min(band.k * room, 30.0))

    def _room(self, o, side: float) -> float:
        """Least distance [m] from the turning circle (``side`` +1 left, -1 right) to a wall, beyond half a body."""
        return circle_room(o.x, o.y, math.atan2(o.sin_psi, o.cos_psi), side, self.turn_radius) - self.half_length

    def _room_ahead(self, o) -> float:
        """Distance [m] along the heading from the nose to the first wall."""
        return tank.distance_ahead(o.x, o.y, o.cos_psi, o.sin_psi) - self.half_length


def _wrap(angle: float) -> float:
    """Angle wrapped to [-pi, pi) [rad]."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi
