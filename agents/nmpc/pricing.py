"""How the NMPC prices a plan: its rollout, the hand law as base policy, the turns beyond the horizon, goal reach.

:class:`PlanPricing` is a mixin of :class:`pectoral_gym.agents.nmpc.controller.NMPCController` (it uses the controller's
``problem``, ``settings``, ``hand``, ``spin``, ``gains``, bounds and ``_target_end``). Everything here runs on
the planning model (the averaged model with the identified K), never on the full model:

* :meth:`PlanPricing._rollout_cost`: a candidate's cost, the NLP's objective on the model's rollout plus what lies
  beyond the horizon (the screening ranks the candidates by it; a solve is kept only if it costs no more);
* :meth:`PlanPricing._spin_plan`: the cheapest on-the-spot turn (:mod:`pectoral_gym.agents.nmpc.spin`), priced the
  same way;
* :meth:`PlanPricing._hand_loop`: the hand law (:class:`pectoral_gym.agents.baselines.HandController`) in closed
  loop on the model, the screening's hand candidate and the continuation beyond the horizon;
* :meth:`PlanPricing._continuation` and :meth:`PlanPricing._togo`: the cost beyond the horizon;
* :meth:`PlanPricing._reach_cost`: a plan whose rollout enters the goal is priced up to that interval
  only (the episode ends there with success; the NLP's distance to the goal's centre would otherwise
  prefer a slow approach to the centre over swimming through the goal circle).
"""

from __future__ import annotations

import math

import numpy as np

from pectoral_gym.agents.controllers.stop_band import band_violation
from pectoral_gym.agents.controllers.turning import circle_room, turn_paths
from pectoral_gym.agents.nmpc.problem import FinInputs, pack_decision, to_z
from pectoral_gym.envs.observation import Observation
from pectoral_gym.model.symbolic import STATE_PSI, STATE_VELOCITY
from pectoral_gym.model.tank import wall_shortfall

__all__ = ["PlanPricing"]


class PlanPricing:
    """Mixin of the NMPC controller: a plan's cost on the model, the hand law there, costs past the horizon, spins.

    The controller is :class:`pectoral_gym.agents.nmpc.controller.NMPCController`.
    """

    def _hand_input(self, x: np.ndarray, ref: np.ndarray, vref: np.ndarray, rate: float) -> np.ndarray:
        """The hand law's inputs (a :class:`FinInputs` row, clipped to the planner's bounds) at the model state."""
        c, s_ = math.cos(x[STATE_PSI]), math.sin(x[STATE_PSI])
        ex, ey = ref[0] - x[0], ref[1] - x[1]
        o = Observation(float(x[0]), float(x[1]), c, s_, float(x[3]), float(x[4]), float(x[5]),
                        c * ex + s_ * ey, -s_ * ex + c * ey, c * vref[0] + s_ * vref[1],
                        -s_ * vref[0] + c * vref[1], np.zeros(8))
        b_r, a_r, b_l, a_l = self.hand.command(o, rate)
        return np.clip(FinInputs(a_r, a_l, b_r, b_l), self.u_low, self.u_high)

    def _hand_loop(self, x: np.ndarray, z_prev: np.ndarray, rate: float, ref: np.ndarray, vref: np.ndarray,
                   steps: int):
        """The hand law in closed loop on the planning model for ``steps`` intervals from ``x``.

        Yields ``(inputs, end state)`` per interval; the law's yaw rate is the model's mean over the
        interval before. Stops early at a non-finite state.
        """
        dt = self.dt
        for k in range(steps):
            u = self._hand_input(x, ref + vref * k * dt, vref, rate)
            z = to_z(u)
            end = np.asarray(self.problem.interval(x, z, z_prev, self.gains)[0]).ravel()
            if not np.all(np.isfinite(end)):
                return
            yield u, end
            rate = ((end[STATE_PSI] - x[STATE_PSI] + math.pi) % (2 * math.pi) - math.pi) / dt
            x, z_prev = end, z

    def _hand_guess(self, state: np.ndarray, ref: np.ndarray, vref: np.ndarray) -> np.ndarray:
        """Inputs ``(4, horizon)`` of the hand law in closed loop on the planning model.

        The law is :class:`pectoral_gym.agents.baselines.HandController`. Each interval, the law sees the
        model's predicted pose and the target (moved with its velocity).
        """
        u = np.tile(self._u_prev[:, None], (1, self._n))
        k = -1
        for k, (u_k, _) in enumerate(self._hand_loop(state, to_z(self._u_prev), float(state[STATE_VELOCITY][2]),
                                                     ref, vref, self._n)):
            u[:, k] = u_k
        if 0 <= k < self._n - 1:
            u[:, k + 1:] = u[:, k:k + 1]
        return u

    def _continuation(self, x: np.ndarray, z_last: np.ndarray) -> float:
        """Cost beyond the horizon: the hand law continued on the model for ``togo_steps`` intervals.

        Per interval the NLP's distance and wall terms (wall margin ``togo_wall_margin``), until the
        goal radius is reached; else the whole turn-then-straight path from where it ends, weighted by
        ``w_togo`` (the distance left must count here: a plan that waits would otherwise cost no more).
        """
        s = self.settings
        goal = np.asarray(self._target_end)
        cost, end = 0.0, x
        for _, end in self._hand_loop(x, z_last, 0.0, goal, np.zeros(2), s.togo_steps):
            d = math.hypot(goal[0] - end[0], goal[1] - end[1])
            cost += s.w_distance * d + s.w_wall * self._wall_violation(end, s.togo_wall_margin)
            if d < self.config.goal_radius:
                return cost
        return cost + self.w_togo * (self._togo(end) + math.hypot(goal[0] - end[0], goal[1] - end[1]))

    def _wall_violation(self, x: np.ndarray, margin: float) -> float:
        """Sum of the squared shortfalls [m^2] of nose and tail below ``margin`` from each wall (the NLP's term).

        With the robot's stopping-distance band (:attr:`NMPCSettings.stop_band`), the NLP's band term instead
        (``margin`` unused: the band has its own).
        """
        band = self.problem.stop_band
        if band is not None:
            return float(band_violation(x[0], x[1], x[STATE_PSI], x[3], x[4], band, np))
        c, s_ = math.cos(x[STATE_PSI]), math.sin(x[STATE_PSI])
        return float(wall_shortfall(x[0], x[1], c, s_, self._half_length, margin))

    def _togo(self, end: np.ndarray) -> float:
        """Turn-then-straight path [m] from the state ``end`` to the target, minus the straight distance.

        The arc of a turn whose circle leaves less than :attr:`NMPCSettings.togo_wall_margin` to a wall
        (beyond half a body) counts longer, by the missing room over the margin: a turn along a wall is
        charged, a path that needs no turn is not.
        """
        (gx, gy), s = self._target_end, self.settings
        x, y, psi = float(end[0]), float(end[1]), float(end[STATE_PSI])
        radius, margin = s.turn_radius, s.togo_wall_margin
        best = math.inf
        for side, (arc, straight) in zip((1.0, -1.0), turn_paths(x, y, psi, gx, gy, radius), strict=True):
            factor = 1.0
            if margin > 0:
                room = circle_room(x, y, psi, side, radius) - self._half_length
                factor += max((margin - room) / margin, 0.0)
            best = min(best, radius * arc * factor + straight)
        return best - math.hypot(gx - x, gy - y)

    def _reach_cost(self, x: np.ndarray) -> float | None:
        """Cost of a rollout ``x (6, horizon + 1)`` that enters the goal: priced up to the first interval inside.

        ``goal`` only, with :attr:`NMPCSettings.reach_fraction` > 0: the first interval end within
        ``reach_fraction`` of the goal radius ends the plan (the episode ends there); its cost is the
        NLP's distance and wall terms up to and including that interval. ``None`` if the rollout
        stays outside (or for ``track``).
        """
        s = self.settings
        if self.track or not s.reach_fraction > 0:
            return None
        gx, gy = self._target_end
        d = np.hypot(x[0, 1:] - gx, x[1, 1:] - gy)
        inside = np.flatnonzero(d < s.reach_fraction * self.config.goal_radius)
        if inside.size == 0:
            return None
        k = int(inside[0])
        walls = sum(self._wall_violation(x[:, j + 1], s.wall_margin) for j in range(k + 1))
        return float(s.w_distance * d[: k + 1].sum() + s.w_wall * walls)

    def _rollout_cost(self, state: np.ndarray, p: np.ndarray, u: np.ndarray,
                      deep: bool = True) -> tuple[float, np.ndarray]:
        """Cost of the model's rollout under the inputs ``u (4, horizon)`` (clipped, blocked), and those ``z``.

        A rollout that enters the goal costs its distance and wall terms up to there (:meth:`_reach_cost`).
        Else, beyond the horizon: with ``deep`` and :attr:`NMPCSettings.togo_steps`, the hand law's continuation
        (:meth:`_continuation`), else the turn-then-straight cost-to-go (:meth:`_togo`).
        """
        problem = self.problem
        z = problem.blocked(np.clip(to_z(u), self.z_low[:, None], self.z_high[:, None]))
        x = np.asarray(problem.rollout(state, z[:, problem.block_of], to_z(self._u_prev), self.gains))
        cost = float(problem.cost(np.nan_to_num(pack_decision(z, x)), p)) if np.all(np.isfinite(x)) else math.inf
        reach = self._reach_cost(x) if math.isfinite(cost) else None
        if reach is not None:  # the plan enters the goal: nothing beyond that interval counts
            cost = reach
        elif math.isfinite(cost):
            if deep and self.settings.togo_steps > 0 and not self.track:
                cost += self._continuation(x[:, -1], z[:, -1])
            elif self.w_togo > 0:  # beyond the horizon: the turn still to make
                cost += self.w_togo * self._togo(x[:, -1])
        return (cost if math.isfinite(cost) else math.inf), np.nan_to_num(pack_decision(z, x))

    def _spin_plan(self, state: np.ndarray, ref: np.ndarray, p: np.ndarray) -> tuple[float, np.ndarray, None] | None:
        """The cheapest spin candidate as ``(cost, plan (horizon, 4), None)``, or ``None``.

        The candidates are :mod:`pectoral_gym.agents.nmpc.spin`'s turns.

        Priced as the NLP's candidates are: the objective's state terms on the rollout plus its input terms,
        or the reach cost; the shallow ranking adds the turn-then-straight cost-to-go, the cheapest one is
        priced again with the hand law's continuation (:attr:`NMPCSettings.togo_steps`).
        """
        spin, problem, s = self.spin, self.problem, self.settings
        u, x, work = spin.rollouts(state, ref)
        # the fin work of the strokes swept (a spin's is mostly in its transitional strokes), as the NLP's
        # energy term prices it for regular beats
        inputs = problem.energy_weight * work + spin.input_cost(u, self._u_prev, problem.input_width, s.w_change)
        costs = np.full(len(x), math.inf)
        within = np.full(len(x), math.nan)  # the objective's terms within the horizon, of rollouts that miss the goal
        for i in np.flatnonzero(np.all(np.isfinite(x), axis=(1, 2))):
            reach = self._reach_cost(x[i])
            if reach is not None:
                costs[i] = reach
            else:
                within[i] = float(problem.state_cost(x[i], p)) + inputs[i]
                costs[i] = within[i] + self.w_togo * self._togo(x[i][:, -1])
        i = int(np.argmin(costs))
        if not math.isfinite(costs[i]):
            return None
        cost = costs[i]
        if not math.isnan(within[i]) and s.togo_steps > 0 and not self.track:
            cost = within[i] + self._continuation(x[i][:, -1], to_z(u[i][-1]))
        return float(cost), u[i].copy(), None
