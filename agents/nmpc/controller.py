"""NMPC baseline: plans fin-beat parameters on the averaged model with CasADi, in real time.

The problem (:class:`pectoral_gym.agents.nmpc.problem.NMPCProblem`: model, inputs, move blocks, latching delay,
cost) is built once per controller (:class:`NMPCController`), parametric in the current state, the
target and its velocity, and the fin command still being latched. Each control period:

1. screening: candidate plans (the last plan shifted by one interval; swim straight; turn left or
   right, held or (``goal``) for 2 s then straight; the hand law in closed loop on the model) are rolled out on
   the model and ranked by the NLP's cost plus the cost beyond the horizon, or, for a rollout that
   enters the goal, by its cost up to there (:mod:`pectoral_gym.agents.nmpc.pricing`): a discrete choice of the
   turn direction, which a few iterations from one guess cannot make;
2. a solve from the best candidate (default: 8 SQP iterations, the real-time iteration; the shifted
   plan is warm-started with its shifted multipliers);
3. the solution's inputs are rolled out again and kept only if they cost no more than the candidate
   (an iteration budget may leave the multiple-shooting gaps open; the rollout always obeys the model);
4. ``goal``: on-the-spot turns (:mod:`pectoral_gym.agents.nmpc.spin`), a fin cycle whose transitional strokes the
   NLP's cycle-averaged model cannot represent, are rolled out on the averaged model with its
   transitional strokes and priced the same way; the cheapest is applied as it is when it costs
   less than the solved plan.

Band and stalls. With a stopping band (:attr:`NMPCSettings.stop_band`; the v1 envs', the robot's) every
command passes the hand law's backup shield (:mod:`pectoral_gym.agents.nmpc.shield`): the NLP prices the band
only softly on the cycle-averaged model, the shield sends a command only if a backup manoeuvre out of the band
remains after it. Plans that rest both fins away from the goal, or creep by a goal inside the turning circle,
hand over to the hand law (:mod:`pectoral_gym.agents.nmpc.handover`).

Robustness. A step whose solves fail (exception, non-finite numbers) or end after
:attr:`NMPCSettings.step_budget` is not applied: the controller falls back to the rest of the last
good plan, and when that is used up to a safe command (both fins at rest: the fish glides to a
stop). :attr:`NMPCController.solve_times`, :attr:`NMPCController.failures` and
:attr:`NMPCController.late` record what happened.
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import numpy as np

from pectoral_gym.agents.controllers.fin_map import FinMap, planning_spec
from pectoral_gym.agents.controllers.hand import HandController
from pectoral_gym.agents.nmpc.handover import HandOver
from pectoral_gym.agents.nmpc.pricing import PlanPricing
from pectoral_gym.agents.nmpc.problem import (
    GAIN_THRUST,
    GAIN_YAW,
    FinInputs,
    NMPCProblem,
    identified_bias_range,
    to_u,
    to_z,
)
from pectoral_gym.agents.nmpc.reference import ReferencePredictor
from pectoral_gym.agents.nmpc.settings import NMPCSettings
from pectoral_gym.agents.nmpc.shield import CommandShield
from pectoral_gym.agents.nmpc.spin import SpinTurns
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.envs.observation import OBS_VELOCITY, decode, one_observation
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.symbolic import STATE_POSITION, STATE_PSI, STATE_SIZE, STATE_VELOCITY

__all__ = ["NMPCController", "NMPCSettings"]


class NMPCController(PlanPricing, HandOver):
    """Nonlinear model-predictive control of the fin patterns on the averaged model.

    Args:
        config: The environment settings (ranges, control period, parameters, task).
        settings: :class:`NMPCSettings`; keyword arguments override its fields. Without a ``stop_band`` there, the
            plan keeps out of the env's band where the env ends episodes in it (``config.stop_band``, v1).
        scaling: Scaling functions of the prediction model, or the path of a coefficients file
            (checked against ``config.params`` unless ``config.check_scaling_params`` is off); default:
            the K of the planning spec (:func:`pectoral_gym.agents.controllers.fin_map.planning_spec`: the env's on the
            averaged model). When the file names its identification grid, planned biases stay inside the grid's range.
        **overrides: Fields of :class:`NMPCSettings`.

    Attributes:
        solve_times: Wall time of every solve [s].
        failures: Number of control steps whose solves all failed or ended after
            :attr:`NMPCSettings.step_budget` (a fallback command was used).
        late: Number of those steps whose solves ended after the step budget.
        unstalled: Number of steps the hand law drove because the plans rested too long (``_unstall``).
        circled: Number of steps the hand law drove after the plans crept by a goal inside the turning circle.
        statuses: Solver return status -> count, over all solves.
        plan: The last good plan, ``(horizon, 4)``: amplitude right/left, bias right/left [rad].
    """

    name = "nmpc"

    def __init__(self, config: EnvConfig, settings: NMPCSettings | None = None,
                 scaling: ScalingFunctions | str | Path | None = None, **overrides):
        self.config = config
        base = settings or NMPCSettings()
        self.settings = NMPCSettings(**{**base.__dict__, **overrides}) if overrides else base
        if self.settings.stop_band is None and config.stop_band:
            self.settings = dataclasses.replace(self.settings, stop_band=config.stop_rule)
        path = scaling if isinstance(scaling, (str, Path)) else None
        self.fins = FinMap(config, planning_spec(config, path))
        self.spec = self.fins.spec  # the planning model (the spin turns' rollouts)
        self.scaling = scaling if isinstance(scaling, ScalingFunctions) else self.fins.scaling
        self.track = config.task == "track"
        self.dt = config.control_period
        s = self.settings
        self.velocity = s.velocity if s.velocity != "auto" else ("difference" if config.model == "full" else "obs")
        a_low, a_high = config.amplitude_range
        b_low, b_high = identified_bias_range(config.bias_range, self.scaling)
        span = s.bias_span if s.bias_span != "auto" else 0.0
        if span is not None:  # the biases the full model follows as planned: near the middle
            mid = float(np.clip(self.fins.bias_mid, b_low, b_high))
            b_low, b_high = max(b_low, mid - span), min(b_high, mid + span)
        self.u_low = np.array(FinInputs(a_low, a_low, b_low, b_low))
        self.u_high = np.array(FinInputs(a_high, a_high, b_high, b_high))
        self.bias_mid = float(np.clip(self.fins.bias_mid, b_low, b_high))
        self.u_rest = np.array(FinInputs(a_low, a_low, self.bias_mid, self.bias_mid))
        self.z_low, self.z_high = to_z(self.u_low), to_z(self.u_high)
        use_hand = s.hand_candidate if s.hand_candidate is not None else config.task != "track"
        # the base policy of the candidate and the continuation
        self.hand = HandController(config, shield=False, scaling=path)
        self.hand_candidate = bool(use_hand)
        self.w_togo = s.w_togo if s.w_togo is not None else (0.0 if self.track else 3.0)
        self.turn_then_straight = bool(s.turn_then_straight if s.turn_then_straight is not None else not self.track)
        self.reference = ReferencePredictor(self.dt, s.horizon, s.reference or ("conic" if self.track else "line"))
        self._target_end = (0.0, 0.0)
        self._half_length = 0.5 * config.params.body_length
        self.problem = NMPCProblem(config, s, self.fins, self.scaling, self.z_low, self.z_high)
        strong = 0.6 * FinInputs(*self.u_high).amplitude_right
        self._straight = np.array(FinInputs(strong, strong, self.bias_mid, self.bias_mid))  # screened, and after spins
        self.spin = None
        if s.spin if s.spin is not None else not self.track:
            spin = SpinTurns(config, self.fins, self.scaling, s.horizon, self._straight, spec=self.spec)
            self.spin = spin if spin.available else None
        self.shield = None  # the hard guard against the band: the NLP only prices it
        if s.shield if s.shield is not None else s.stop_band is not None:
            self.shield = CommandShield(config, self.fins, s.stop_band, s.shield_margin, s.shield_spread,
                                        s.shield_spin, s.shield_firmware, s.shield_keep_side, s.shield_reserve)
        self._solver = self.problem.solver  # the controller calls it through this attribute (tests replace it)
        self._n = self.problem.horizon
        self.n_delay_steps = self.problem.n_delay_steps
        self.solve_times: list[float] = []
        self.failures = 0
        self.late = 0
        self.statuses: dict[str, int] = {}
        self.unstalled = self.circled = 0
        self.reset()

    # ------------------------------------------------------------------ controller protocol
    def reset(self, seed: int | None = None) -> None:
        """Start of an episode: forget the plan, the warm start and the previous observation."""
        self.plan: np.ndarray | None = None
        self._plan_age = 0
        self._u_prev = self.u_rest.copy()
        self._prev_obs: np.ndarray | None = None
        self._last: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._duals: tuple[np.ndarray, np.ndarray] | None = None  # lam_x, lam_g of the last good solve
        self.reference.reset()
        self.gains = np.array(self.settings.initial_gains, dtype=np.float64)
        self._plan_spins = False  # the plan is a spin candidate (not the NLP's: no multipliers, no shifted guess)
        self._spun = (False, False)  # whether the last two commands were spin steps
        self._reset_hand_over()
        if self.spin is not None:
            self.spin.reset()
        if self.shield is not None:
            self.shield.reset()

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Solve the NMPC problem for one observation ``(19,)``; returns the normalised action ``(8,)``."""
        obs = one_observation(obs)  # the fin block (observe_fins), if any, is not read
        backup_spin = False
        if not np.all(np.isfinite(obs)):
            u = self._fallback()
        else:
            state, ref, vref = self._estimate(obs)
            if self._last is not None and not any(self._spun):  # the NLP's model has no spin to compare with
                before, z_applied, z_before = self._last
                end, v_mean = (np.asarray(v).ravel()
                               for v in self.problem.interval(before, z_applied, z_before, self.gains))
                if self.settings.adapt_rate > 0:
                    self._adapt(state)
                if self.settings.observer and np.all(np.isfinite(end)):
                    # the observation holds velocities averaged over the last period: they lag the
                    # current ones; shift the model's end-of-period velocities by the measured offset
                    state[STATE_VELOCITY] = end[STATE_VELOCITY] + (state[STATE_VELOCITY] - v_mean)
            failures = self.failures
            u = planned = self._plan_step(state, ref, vref)
            if self.failures == failures:  # a fallback's rest is the safe command, not a stall
                u = self._unstall(state, ref, vref, u)
            if self.shield is not None:  # a spin sent instead of the plan (hand-over or backup) is no NLP motion
                u = self.shield.filter(state, u, ref)
                backup_spin = self.shield.spun(planned, u)
            self._last = (state, to_z(u), to_z(self._u_prev))
        self._spun = (self._spun[1], (self._plan_spins and self.plan is not None) or backup_spin)
        if self.spin is not None:
            self.spin.applied(u)
        if self.shield is not None:
            self.shield.applied(u)
        self._prev_obs = obs.copy()
        self._u_prev = u
        u = FinInputs(*u)
        return self.fins.action(u.bias_right, u.amplitude_right, u.bias_left, u.amplitude_left)

    # ------------------------------------------------------------------ internals
    def _estimate(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """State ``(6,)``, target position and target velocity (tank frame) from an observation."""
        o = decode(obs)
        psi = math.atan2(o.sin_psi, o.cos_psi)
        velocity = obs[OBS_VELOCITY].copy()
        prev = self._prev_obs
        if self.velocity == "difference" and prev is not None and np.all(np.isfinite(prev)):
            p = decode(prev)
            psi_prev = math.atan2(p.sin_psi, p.cos_psi)
            dpsi = (psi - psi_prev + math.pi) % (2 * math.pi) - math.pi
            mid = psi_prev + 0.5 * dpsi
            dx, dy = (o.x - p.x) / self.dt, (o.y - p.y) / self.dt
            velocity = np.array([math.cos(mid) * dx + math.sin(mid) * dy,
                                 -math.sin(mid) * dx + math.cos(mid) * dy, dpsi / self.dt])
        state = np.array([o.x, o.y, psi, *velocity])  # the STATE_* layout of pectoral_gym.model.symbolic
        ref = np.array(o.target_in_tank())
        vref = np.array(o.target_velocity_in_tank()) if self.track else np.zeros(2)
        if self.track:
            self.reference.observe(ref, vref)
        return state, ref, vref

    def _adapt(self, state: np.ndarray) -> None:
        """Correct the thrust and yaw-moment gains from the last interval: measured vs predicted motion.

        At a steady state the yaw rate and the speed grow with the square root of the moment and
        the thrust; the gains move by ``(measured / predicted)^(2 rate)`` in log space (ratios clipped to
        [0.5, 2], gains to ``gain_bounds``), and only when the prediction moved enough to compare.
        """
        s = self.settings
        before, z_applied, z_before = self._last
        plan = np.repeat(z_applied[:, None], self._n, axis=1)
        predicted = np.asarray(self.problem.rollout(before, plan, z_before, self.gains))[:, 1]
        turn_pred = predicted[STATE_PSI] - before[STATE_PSI]
        turn_meas = (state[STATE_PSI] - before[STATE_PSI] + math.pi) % (2 * math.pi) - math.pi
        move_pred = float(np.hypot(*(predicted[STATE_POSITION] - before[STATE_POSITION])))
        move_meas = float(np.hypot(*(state[STATE_POSITION] - before[STATE_POSITION])))
        low, high = s.gain_bounds
        if abs(turn_pred) > 0.03 and turn_pred * turn_meas > 0:
            ratio = float(np.clip(turn_meas / turn_pred, 0.5, 2.0))
            self.gains[GAIN_YAW] = float(np.clip(self.gains[GAIN_YAW] * ratio ** (2 * s.adapt_rate), low, high))
        if move_pred > 0.01 and move_meas > 0:
            ratio = float(np.clip(move_meas / move_pred, 0.5, 2.0))
            self.gains[GAIN_THRUST] = float(np.clip(self.gains[GAIN_THRUST] * ratio ** (2 * s.adapt_rate), low, high))

    def _fresh_guesses(self) -> list[np.ndarray]:
        """Input sequences ``(4, horizon)`` to screen: straight; turn left/right (held, or for 2 s then straight).

        The turns for 2 s then straight only with :attr:`NMPCSettings.turn_then_straight` (default: ``goal``).
        """
        a_high, mid = FinInputs(*self.u_high).amplitude_right, self.bias_mid
        strong, weak, tight, least = 0.6 * a_high, 0.15 * a_high, 0.4 * a_high, 0.05 * a_high
        turn_steps = min(self._n, max(1, int(round(2.0 / self.dt))))
        straight = self._straight
        guesses = [np.tile(straight[:, None], (1, self._n))]
        for pair in ((strong, weak), (weak, strong), (tight, least), (least, tight)):  # right fin stronger: left
            turn = np.array(FinInputs(*pair, mid, mid))
            guesses.append(np.tile(turn[:, None], (1, self._n)))
            if self.turn_then_straight:
                then = np.tile(straight[:, None], (1, self._n))
                then[:, :turn_steps] = turn[:, None]
                guesses.append(then)
        return guesses

    def _solve(self, state: np.ndarray, p: np.ndarray, u_guess: np.ndarray,
               duals: tuple[np.ndarray, np.ndarray] | None = None, guess_cost: float | None = None):
        """One solve from ``u_guess`` ``(4, horizon)`` (and multipliers ``duals``; ``guess_cost``: its cost if known).

        The solve starts feasible (its state guess is the model's rollout under the guess). Its inputs
        are simulated again on the model, and the rollout's cost decides: the solution is used if it
        costs no more than the guess, else the guess itself (also a plan that obeys the model). With a
        fixed iteration budget the solver's own states need not close the shooting gaps exactly.

        Returns ``(cost, plan (horizon, 4), (lam_x, lam_g) or None)``, or ``None`` if neither is usable.
        """
        problem = self.problem
        if guess_cost is None:
            guess_cost, x0 = self._rollout_cost(state, p, u_guess)
        else:  # priced by the screening already: only the rollout is needed
            x0 = self._rollout_cost(state, p, u_guess, deep=False)[1]
        warm = {} if duals is None else {"lam_x0": duals[0], "lam_g0": duals[1]}
        sol = self._solver(x0=x0, p=p, lbx=problem.lbx, ubx=problem.ubx, lbg=0.0, ubg=0.0, **warm)
        status = self._solver.stats().get("return_status", "")
        self.statuses[status] = self.statuses.get(status, 0) + 1
        z = problem.inputs(sol["x"])
        if np.all(np.isfinite(z)):
            plan = np.clip(to_u(z).T, self.u_low, self.u_high)
            cost, _ = self._rollout_cost(state, p, plan.T)
            if cost <= guess_cost:
                return cost, plan, (np.asarray(sol["lam_x"]).ravel(), np.asarray(sol["lam_g"]).ravel())
        if not math.isfinite(guess_cost):
            return None
        return guess_cost, np.clip(to_u(problem.inputs(x0)).T, self.u_low, self.u_high), None

    def _plan_step(self, state: np.ndarray, ref: np.ndarray, vref: np.ndarray) -> np.ndarray:
        """Screen the candidates, solve from the best (the next one if that fails); the plan's first input."""
        start = time.perf_counter()
        budget = self.settings.step_budget
        best = spin = None
        try:
            guesses = self._fresh_guesses()
            duals = [None] * len(guesses)
            if self.plan is not None and not self._plan_spins:  # the shifted last plan, with its multipliers
                age = self._plan_age + 1
                guesses.insert(0, np.vstack([self.plan[age:], np.repeat(self.plan[-1:], age, 0)]).T)
                duals.insert(0, self._shifted_duals(age))
            if self.hand_candidate:  # the hand law's closed loop on the model: its turn rules in one plan
                guesses.append(self._hand_guess(state, ref, vref))
                duals.append(None)
            path = self.reference.predict(ref, vref) if self.track else None
            p = self.problem.parameters(state, ref, vref, to_z(self._u_prev), self.gains, path)
            self._target_end = tuple(p[STATE_SIZE + 2 * self._n - 2: STATE_SIZE + 2 * self._n])  # the last ref
            # screening: rollouts, no solve; the cheapest few (and the hand law's) again with the continuation
            costs = [self._rollout_cost(state, p, u, deep=False)[0] for u in guesses]
            if self.settings.togo_steps > 0 and not self.track:
                deep = set(sorted(range(len(guesses)), key=costs.__getitem__)[: self.settings.deep_candidates])
                deep |= {len(guesses) - 1} if self.hand_candidate else set()
                costs = [self._rollout_cost(state, p, guesses[k])[0] if k in deep else math.inf
                         for k in range(len(guesses))]
            spin = self._spin_plan(state, ref, p) if self.spin is not None else None
            solves = 0
            for k in sorted(range(len(guesses)), key=costs.__getitem__):  # the next one only if a solve failed
                if solves >= self.settings.max_solves + (best is None) or time.perf_counter() - start > budget:
                    break
                solves += 1
                result = self._solve(state, p, guesses[k], duals[k], costs[k])
                if result is not None and (best is None or result[0] < best[0]):
                    best = result
            if spin is not None and (best is None or spin[0] < best[0]):
                best = spin
        except Exception:  # noqa: BLE001 - a failed solve must never stop the fish controller
            best = None
        elapsed = time.perf_counter() - start
        self.solve_times.append(elapsed)
        if elapsed > budget:  # too late for this control period: the command must not wait for it
            self.late += 1
            best = None
        if best is None:
            self.failures += 1
            return self._fallback()
        self.plan, self._duals = best[1], best[2]
        self._plan_spins = best is spin
        self._plan_age = 0
        return self.plan[0].copy()

    def _shifted_duals(self, age: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The last good solve's multipliers, the state constraints' shifted by ``age`` intervals."""
        if self._duals is None:
            return None
        lam_x, lam_g = self._duals
        shift = STATE_SIZE * age
        lam_g = np.concatenate([lam_g[shift:], np.tile(lam_g[-STATE_SIZE:], age)]) if shift < lam_g.size else lam_g
        return lam_x, lam_g

    def _fallback(self) -> np.ndarray:
        """Next step of the last good plan, or the rest command once it is used up."""
        if self.plan is not None and self._plan_age + 1 < self.plan.shape[0]:
            self._plan_age += 1
            return self.plan[self._plan_age].copy()
        return self.u_rest.copy()
