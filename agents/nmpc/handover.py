"""When the hand law drives instead of the NMPC's plan: stalls and goals inside the turning circle.

:class:`HandOver` is a mixin of :class:`pectoral_gym.agents.nmpc.controller.NMPCController` (it uses the
controller's ``settings``, ``config``, ``track``, ``u_rest``, ``_plan_spins`` and
:meth:`~pectoral_gym.agents.nmpc.pricing.PlanPricing._hand_input`). ``goal`` only. Two situations the plan does not
get out of by itself on the emulated robot:

* a stall (:attr:`NMPCSettings.stall_steps`): plans that rest both fins with the fish nearly still away from
  the goal; the hand law, which always moves off, drives until a plan moves again;
* a goal inside the turning circle (:attr:`NMPCSettings.circle_steps`): the fish (~0.25 m turning radius, ~0.3 m on
  the emulated robot) cannot turn into a goal that lies inside either circle, and the way round (swim on, then turn
  back) is longer than the 5 s horizon. The plans then send 1-4 deg amplitudes and creep at ~0.01 m/s (lockstep tuning
  seed 7412: from 24 s to 69 s it drifted from 0.12 to 0.35 m off the goal; a time-out). When the distance has not
  fallen by ``circle_progress`` over ``circle_steps`` steps with the goal inside the circle, the hand law drives for
  the rest of the episode (:meth:`~pectoral_gym.agents.controllers.hand.HandController.command`: swim straight on
  until the goal is out of its circle, turn to it, steer all the way in). Handing back once the fish faced the goal
  (within 25 deg) left the last 0.2 m to the plan, whose coasting arrivals curved past the goal on the robot (tuning
  seeds 7400-7419: 16 goals, 3 time-outs, against 17 and 3 before the hand-over). Not the hand law's on-the-spot spin:
  through the robot's command path the spin cycle moves the fish at 0.03-0.06 m/s on a circle about as wide as a plain
  turn's (seed 7407: spun round the goal from 22 s to the time-out; seed 7411: a geofence stop in the spin).

Every command, the hand law's too, then passes the shield (:mod:`pectoral_gym.agents.nmpc.shield`).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from pectoral_gym.agents.controllers.turning import inside_turning_circle
from pectoral_gym.agents.nmpc.problem import FinInputs
from pectoral_gym.model.symbolic import STATE_PSI, STATE_VELOCITY

__all__ = ["HandOver", "goal_bearing"]

_REST_MARGIN = math.radians(1.0)  # rad: a fin "at rest" beats at most this far above the lowest amplitude


def goal_bearing(state: np.ndarray, goal: np.ndarray) -> tuple[float, float]:
    """Distance [m] and bearing [rad] in ``[-pi, pi)`` (> 0: to the left) of ``goal (X, Y)`` from ``state``."""
    ex, ey = goal[0] - state[0], goal[1] - state[1]
    bearing = (math.atan2(ey, ex) - state[STATE_PSI] + math.pi) % (2.0 * math.pi) - math.pi
    return math.hypot(ex, ey), bearing


class HandOver:
    """Mixin of the NMPC controller: the hand law takes over from plans that stall or circle a goal."""

    def _reset_hand_over(self) -> None:
        """Start of an episode: no resting plans counted, no distances remembered, the plan drives."""
        self._rest_amplitude = FinInputs(*self.u_rest).amplitude_right + _REST_MARGIN
        self._rest_steps = 0  # consecutive plans that rest both fins
        self._distances: deque[float] = deque(maxlen=max(int(self.settings.circle_steps), 0) + 1)
        self._circling = False  # the hand law drives to the end: the plan crept by a goal inside the circle

    def _unstall(self, state: np.ndarray, ref: np.ndarray, vref: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The plan's inputs ``u (4,)``, or the hand law's where the plan stalls or circles the goal.

        Args:
            state: Body state ``(X, Y, psi, vx, vy, omega)`` [m, m, rad, m/s, m/s, rad/s].
            ref: The goal ``(X, Y)`` [m].
            vref: The goal's velocity [m/s] (zero for ``goal``).
            u: The plan's first inputs (``FinInputs`` order: amplitudes, biases [rad]).

        Returns:
            The inputs to send (before the shield). :attr:`unstalled` and :attr:`circled` count the steps the
            hand law drove for each reason.
        """
        s = self.settings
        if self.track:
            return u
        distance, bearing = goal_bearing(state, ref)
        if self._circle(distance, bearing):
            self.circled += 1
            return self._hand_input(state, ref, vref, float(state[STATE_VELOCITY][2]))
        resting = bool(np.all(FinInputs(*u)[:2] <= self._rest_amplitude))
        self._rest_steps = self._rest_steps + 1 if resting else 0
        slow = math.hypot(state[3], state[4]) < s.stall_speed
        if s.stall_steps <= 0 or self._rest_steps < s.stall_steps or not slow or distance <= self.config.goal_radius:
            return u
        self.unstalled += 1
        return self._hand_input(state, ref, vref, float(state[STATE_VELOCITY][2]))

    def _circle(self, distance: float, bearing: float) -> bool:
        """Whether the hand law drives: the goal was inside the circle with no progress (now or before)."""
        s = self.settings
        if self._plan_spins:  # a planned spin (simulation) turns to the goal on the spot: it closes no distance
            self._distances.clear()
        self._distances.append(distance)
        if s.circle_steps <= 0 or self._circling:
            return self._circling
        if inside_turning_circle(distance, bearing, s.turn_radius) and len(self._distances) == self._distances.maxlen:
            self._circling = self._distances[0] - distance < s.circle_progress
        return self._circling
