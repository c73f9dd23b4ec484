"""NMPC baseline: plans fin-beat parameters on the averaged model with CasADi and IPOPT.

The problem is built once per controller (:class:`NMPCController`), parametric in the current state,
the target and its velocity, and the fin command still being latched; each control period it is
solved again, warm-started from the previous plan shifted by one interval.

Model and inputs. The prediction model is the cycle-averaged model of
:mod:`pectoral_gym.symbolic` (eq. 25 with the identified scaling functions
``ScalingFunctions.load()``, body dynamics eqs. 19-20). The inputs are the amplitude and the bias of
each fin, held constant over each control interval. The period and the ratio are fixed at the
shortest period and the largest ratio of the env's ranges: the averaged thrust,
``k pi^2 (zeta^2 - 1) / (zeta T_p^2) gA J1(gA) sin g0``, grows monotonically as ``T_p`` falls and
``zeta`` rises, so these values give the most control authority for a given amplitude, and the
shortest period makes a fin latch a new pattern soonest (a fin switches only at a stroke turning
point). The amplitude then sets the thrust (a continuous, monotone input) and the bias its
direction, so nothing the problem needs is lost, and two fewer inputs per fin keep the solve fast.

Latching delay. A new command takes effect at the fin's next turning point. The first interval
is therefore integrated with the previous command for ``latch_delay`` seconds (default: the mean
wait, ``(zeta^2 + 1) T_p / (2 (zeta + 1)^2)``, for a random phase of the stroke), then with the new one.

Cost (per interval ``k`` of the horizon, position ``p_k`` at its end):
``w_distance |p_k - r_k|`` (``r_k`` the goal, or the reference point extrapolated with its
velocity for ``track``; the env's own tracking penalty), a terminal ``w_terminal |p_N - r_N|``,
the fin work ``energy_weight sum_fins P(gA) dt`` (the env's energy term, mean fin power of
:func:`pectoral_gym.averaging.mean_fin_power`), input changes ``w_change |du|^2`` (normalised by the
ranges) and a soft wall constraint ``w_wall sum max(0, margin - distance of nose/tail to wall)^2``.

Robustness. A solve that fails (IPOPT status, exception, non-finite numbers) is not used: the
controller falls back to the rest of the last good plan, and when that is used up to a safe
command (both fins at rest: the fish glides to a stop). :attr:`NMPCController.solve_times` and
:attr:`NMPCController.failures` record what happened.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from agents.fin_map import FinMap
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.kfunctions import ScalingFunctions
from pectoral_gym.params import TANK_LENGTH, TANK_WIDTH
from pectoral_gym.symbolic import averaged_forcing_sx, body_accel_sx, combined_yaw_oscillation_sx

__all__ = ["NMPCController", "NMPCSettings"]

_GOOD_STATUS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
# A solve stopped by the iteration or time limit is still used when its trajectory obeys the model to
# within this (m, rad, m/s): a feasible if suboptimal plan, the usual real-time NMPC compromise.
_FEASIBLE = 1e-3
_N_U = 4  # squared amplitude right, squared amplitude left, bias right, bias left
_AMPLITUDE_FLOOR = 1e-3  # rad: keeps sqrt(gA^2) differentiable; a 0.06 deg stroke is no stroke


@dataclass(frozen=True)
class NMPCSettings:
    """Settings of the NMPC baseline (fixed once the problem is built).

    Attributes:
        horizon: Number of control intervals predicted.
        substeps: RK4 steps per control interval (the yaw damping needs steps below ~0.1 s).
        latch_delay: Seconds the previous command still acts in the first interval; ``None``: the
            mean wait until a stroke turning point.
        w_distance: Weight of the distance to the goal/reference at each interval end [1/m].
        w_terminal: Extra weight of the distance at the end of the horizon [1/m].
        w_heading: Weight of ``1 - cos(bearing of the target)`` at each interval end.
        heading_scale: Distance [m] below which the heading term fades out.
        w_change: Weight of squared input changes between intervals (inputs scaled to [0, 1]).
        w_reach: Weight of the terminal reachability term: how far the target lies inside the fish's
            turning circle at the end of the horizon [1/m]. The horizon is far shorter than a loop
            (tens of seconds), so without it the fish circles a target it passed closely.
        turn_radius: Smallest turning radius assumed by the reachability term [m] (the full model
            turns no tighter than about 0.23 m; see docs/benchmark.md).
        w_wall: Weight of the squared wall violation [1/m^2].
        wall_margin: Keep nose and tail this far from the walls [m].
        energy_weight: Weight of the fin work [1/J]; ``None``: the env's ``energy_weight``.
        smoothing: Speed scale [m/s] smoothing ``|V|``, ``alpha`` and ``|omega|`` at rest
            (:func:`pectoral_gym.symbolic.body_accel_sx`).
        idle_amplitude: A plan whose mean amplitude is below this fraction of the largest one is
            compared with solves from fresh guesses (straight, turn left, turn right): stopping is a
            common local minimum when every way to the target first leads away from it.
        adapt_rate: Rate of the online correction of the thrust and yaw-moment gains from the measured
            motion (0: no adaptation). The averaged model with placeholder or imperfect K, or a
            randomised fish, turns and swims at other rates than predicted; the gains absorb that.
        gain_bounds: Bounds of the two gains.
        max_iter: IPOPT iteration limit per solve.
        max_cpu_time: IPOPT time limit per solve [s].
        velocity: ``"obs"``: body velocities from the observation (the envs report their means over
            the control period); ``"difference"``: mean velocities over the last control period from
            the change of pose, for observation sources that give instantaneous velocities (the full
            model's swing within each fin beat and alias when sampled once per period); ``"auto"``:
            ``"difference"`` on the full model, ``"obs"`` on the averaged model.
        observer: Turn those period-mean velocities into current ones: the model's velocities at the
            end of the last period plus the offset between the measured and the model's period means.
    """

    horizon: int = 10
    substeps: int = 6
    latch_delay: float | None = None
    w_distance: float = 1.0
    w_terminal: float = 2.0
    w_heading: float = 0.3
    heading_scale: float = 0.05
    w_change: float = 0.02
    w_reach: float = 2.0
    turn_radius: float = 0.25
    w_wall: float = 1000.0
    wall_margin: float = 0.03
    energy_weight: float | None = None
    smoothing: float = 1e-3
    idle_amplitude: float = 0.2
    adapt_rate: float = 0.3
    gain_bounds: tuple[float, float] = (0.1, 3.0)
    max_iter: int = 60
    max_cpu_time: float = 0.35
    velocity: str = "obs"
    observer: bool = True

    def __post_init__(self) -> None:
        if int(self.horizon) < 1 or int(self.substeps) < 1 or int(self.max_iter) < 1:
            raise ValueError("horizon, substeps and max_iter must be >= 1")
        if self.velocity not in ("auto", "obs", "difference"):
            raise ValueError(f"velocity must be 'auto', 'obs' or 'difference', got {self.velocity!r}")
        if self.latch_delay is not None and not self.latch_delay >= 0:
            raise ValueError(f"latch_delay must be >= 0 s or None, got {self.latch_delay!r}")
        if not self.max_cpu_time > 0:
            raise ValueError(f"max_cpu_time must be > 0 s, got {self.max_cpu_time!r}")


def _identified_bias_range(bias_range: tuple[float, float], scaling: ScalingFunctions | None) -> tuple[float, float]:
    """The env's bias range, narrowed to the biases the scaling functions were identified on (if known).

    The K are identified on a grid (``metadata["grid"]["bias_deg"]``); outside it a polynomial K
    extrapolates and can be far off (e.g. a negative ``K_fy``), a spline K is clamped (held
    constant), and in both cases the optimiser would exploit a model that is not identified there.
    """
    low, high = bias_range
    grid = (scaling.metadata.get("grid") or {}) if scaling is not None else {}
    biases = grid.get("bias_deg") if isinstance(grid, dict) else None
    if biases:
        g_low, g_high = math.radians(min(biases)), math.radians(max(biases))
        if max(low, g_low) <= min(high, g_high):
            low, high = max(low, g_low), min(high, g_high)
    return float(low), float(high)


class NMPCController:
    """Nonlinear model-predictive control of the fin patterns on the averaged model.

    Args:
        config: The environment settings (ranges, control period, parameters, task).
        settings: :class:`NMPCSettings`; keyword arguments override its fields.
        scaling: Scaling functions of the prediction model, or the path of a coefficients file
            (default: ``ScalingFunctions.load()``, or K = 1 when ``config.scaling == "none"``). When
            the file names its identification grid, planned biases stay inside the grid's range.
        **overrides: Fields of :class:`NMPCSettings`.

    Attributes:
        solve_times: Wall time of every solve [s].
        failures: Number of control steps whose solves all failed (a fallback command was used).
        statuses: IPOPT return status -> count, over all solves.
        plan: The last good plan, ``(horizon, 4)``: amplitude right/left, bias right/left [rad].
    """

    name = "nmpc"

    def __init__(self, config: EnvConfig, settings: NMPCSettings | None = None,
                 scaling: ScalingFunctions | str | Path | None = None, **overrides):
        self.config = config
        base = settings or NMPCSettings()
        self.settings = NMPCSettings(**{**base.__dict__, **overrides}) if overrides else base
        self.fins = FinMap(config)
        if isinstance(scaling, (str, Path)):
            scaling = ScalingFunctions.load(scaling)
        elif scaling is None and config.scaling != "none":
            scaling = ScalingFunctions.load()
        self.scaling = scaling
        self.track = config.task == "track"
        self.dt = config.control_period
        s = self.settings
        self.velocity = s.velocity if s.velocity != "auto" else ("difference" if config.model == "full" else "obs")
        a_low, a_high = config.amplitude_range
        b_low, b_high = _identified_bias_range(config.bias_range, self.scaling)
        self.u_low = np.array([a_low, a_low, b_low, b_low])
        self.u_high = np.array([a_high, a_high, b_high, b_high])
        self.bias_mid = float(np.clip(self.fins.bias_mid, b_low, b_high))
        self.u_rest = np.array([a_low, a_low, self.bias_mid, self.bias_mid])
        self.z_low, self.z_high = self._to_z(self.u_low), self._to_z(self.u_high)
        self._build()
        self.solve_times: list[float] = []
        self.failures = 0
        self.statuses: dict[str, int] = {}
        self.reset()

    # ------------------------------------------------------------------ problem
    @staticmethod
    def _to_z(u: np.ndarray) -> np.ndarray:
        """Physical inputs (amplitudes, biases) -> decision variables (squared amplitudes, biases)."""
        z = np.array(u, dtype=np.float64, copy=True)
        z[:2] = np.maximum(z[:2], _AMPLITUDE_FLOOR) ** 2
        return z

    @staticmethod
    def _to_u(z: np.ndarray) -> np.ndarray:
        """Decision variables -> physical inputs."""
        u = np.array(z, dtype=np.float64, copy=True)
        u[:2] = np.sqrt(np.maximum(u[:2], 0.0))
        return u

    def _build(self) -> None:
        s, cfg, fins = self.settings, self.config, self.fins
        params = cfg.params
        n, m = int(s.horizon), int(s.substeps)
        h = self.dt / m
        zeta, period = fins.ratio, fins.period
        delay = s.latch_delay if s.latch_delay is not None else (zeta**2 + 1) * period / (2 * (zeta + 1) ** 2)
        n_delay = min(m, int(round(delay / h)))

        # Inputs: squared amplitudes (thrust ~ gA J1(gA) ~ gA^2 / 2 has a non-zero gradient at rest in
        # gA^2, not in gA) and biases. The forcing is constant over an interval: computed once per interval.
        u = ca.SX.sym("u", _N_U)
        amp_r, amp_l = ca.sqrt(u[0]), ca.sqrt(u[1])
        right = averaged_forcing_sx(ca.vertcat(u[2], amp_r, period, zeta), 1.0, params, self.scaling)
        left = averaged_forcing_sx(ca.vertcat(u[3], amp_l, period, zeta), -1.0, params, self.scaling)
        # both fins share period and ratio, so they beat in phase
        oscillation = combined_yaw_oscillation_sx(
            ca.vertcat(u[2], amp_r, period, zeta), ca.vertcat(u[3], amp_l, period, zeta), self.scaling)
        oscillating = oscillation is not None
        oscillation = oscillation if oscillating else 0.0
        forcing = ca.Function("forcing", [u], [ca.vertcat(right + left, oscillation)])
        x = ca.SX.sym("x", 6)
        f = ca.SX.sym("f", 4)  # fin force and moment, then the yaw-oscillation amplitude
        psi, vx, vy = x[2], x[3], x[4]
        rhs = ca.Function("rhs", [x, f], [ca.vertcat(
            vx * ca.cos(psi) - vy * ca.sin(psi),  # eq. (19), kinematics
            vx * ca.sin(psi) + vy * ca.cos(psi),
            x[5],
            body_accel_sx(x[3:6], f[:3], params, s.smoothing, f[3] if oscillating else None),  # eqs. (19)-(20)
        )])
        k1 = rhs(x, f)
        k2 = rhs(x + 0.5 * h * k1, f)
        k3 = rhs(x + 0.5 * h * k2, f)
        k4 = rhs(x + h * k3, f)
        step = ca.Function("rk4", [x, f], [x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)])

        # mean fin power (pectoral_gym.averaging.mean_fin_power) with T_p, zeta fixed: power_coef gA^3
        w1 = math.pi * (zeta + 1.0) / period
        power_coef = params.fin_drag_constant * params.fin_span * (w1**2 + (w1 / zeta) ** 2) / period
        energy_weight = cfg.energy_weight if s.energy_weight is None else s.energy_weight
        width = np.where(self.z_high > self.z_low, self.z_high - self.z_low, 1.0)
        half = 0.5 * params.body_length
        turn_radius = float(s.turn_radius)

        p_x0 = ca.SX.sym("x0", 6)
        p_ref = ca.SX.sym("ref", 2)
        p_vref = ca.SX.sym("vref", 2)
        p_zprev = ca.SX.sym("zprev", _N_U)
        Z = ca.SX.sym("Z", _N_U, n)
        X = ca.SX.sym("X", 6, n + 1)
        p_gain = ca.SX.sym("gain", 2)  # online corrections of the thrust and the yaw moment
        gains = ca.vertcat(p_gain[0], p_gain[0], p_gain[1], 1.0)  # the yaw-oscillation amplitude is not scaled
        f_prev = gains * forcing(p_zprev)
        g = [X[:, 0] - p_x0]
        x_roll = [p_x0]
        cost = 0.0
        for k in range(n):
            f_k = gains * forcing(Z[:, k])
            xk, rk = X[:, k], x_roll[-1]
            for j in range(m):
                fj = f_prev if (k == 0 and j < n_delay) else f_k
                xk, rk = step(xk, fj), step(rk, fj)
            g.append(X[:, k + 1] - xk)
            x_roll.append(rk)
            pos, psi = X[0:2, k + 1], X[2, k + 1]
            error = p_ref + p_vref * (k + 1) * self.dt - pos
            dist = ca.sqrt(ca.sumsqr(error) + 1e-6)
            cost += s.w_distance * dist
            if k == n - 1:
                cost += s.w_terminal * dist
                # A target closer than 2 R |sin e| lies inside a turning circle of radius R and cannot be
                # reached by turning towards it (d^2 < 2 R |y_body|); end the horizon where it can.
                lateral = -ca.sin(psi) * error[0] + ca.cos(psi) * error[1]
                inside = 2.0 * turn_radius * ca.sqrt(lateral**2 + 1e-6) - ca.sumsqr(error)
                cost += s.w_reach * ca.fmax(0.0, inside) / turn_radius
            # 1 - cos(bearing of the target): turns the fish towards a target behind it, which a
            # distance cost over a short horizon cannot (turning first moves the fish away)
            facing = (ca.cos(psi) * error[0] + ca.sin(psi) * error[1]) / ca.sqrt(ca.sumsqr(error) + s.heading_scale**2)
            cost += s.w_heading * (1.0 - facing)
            cost += energy_weight * power_coef * (Z[0, k] ** 1.5 + Z[1, k] ** 1.5) * self.dt  # gA^3
            prev = p_zprev if k == 0 else Z[:, k - 1]
            cost += s.w_change * ca.sumsqr((Z[:, k] - prev) / width)
            for sign in (1.0, -1.0):  # nose, tail
                px = X[0, k + 1] + sign * half * ca.cos(psi)
                py = X[1, k + 1] + sign * half * ca.sin(psi)
                for gap in (px, TANK_LENGTH - px, py, TANK_WIDTH - py):
                    cost += s.w_wall * ca.fmax(0.0, s.wall_margin - gap) ** 2
        decision = ca.vertcat(ca.vec(Z), ca.vec(X))
        params_vec = ca.vertcat(p_x0, p_ref, p_vref, p_zprev, p_gain)
        nlp = {"x": decision, "f": cost, "g": ca.vertcat(*g), "p": params_vec}
        options = {
            "print_time": False,
            "error_on_fail": False,
            "show_eval_warnings": False,  # NaN at rejected trial points is handled by IPOPT's line search
            "ipopt": {
                "print_level": 0, "sb": "yes", "max_iter": int(s.max_iter), "max_cpu_time": float(s.max_cpu_time),
                "tol": 1e-5, "acceptable_tol": 1e-3, "acceptable_iter": 5, "mu_strategy": "adaptive",
            },
        }
        self._solver = ca.nlpsol("nmpc", "ipopt", nlp, options)
        self._n = n
        # State bounds keep trial points of the solver where RK4 stays finite (physical values are far inside).
        x_bound = np.tile([np.inf, np.inf, np.inf, 1.0, 1.0, 3.0], n + 1)
        self._lbx = np.concatenate([np.tile(self.z_low, n), -x_bound])
        self._ubx = np.concatenate([np.tile(self.z_high, n), x_bound])
        self._rollout = ca.Function("rollout", [p_x0, Z, p_zprev, p_gain], [ca.horzcat(*x_roll)])
        # One interval from x0 under the applied command: end state and mean body velocities (trapezoid).
        z_applied = ca.SX.sym("z_applied", _N_U)
        xk, f_applied = p_x0, gains * forcing(z_applied)
        v_sum = 0.5 * p_x0[3:6]
        for j in range(m):
            xk = step(xk, f_prev if j < n_delay else f_applied)
            v_sum += xk[3:6] if j < m - 1 else 0.5 * xk[3:6]
        self._interval = ca.Function("interval", [p_x0, z_applied, p_zprev, p_gain], [xk, v_sum / m])
        self.n_delay_steps = n_delay

    # ------------------------------------------------------------------ controller protocol
    def reset(self, seed: int | None = None) -> None:
        """Start of an episode: forget the plan, the warm start and the previous observation."""
        self.plan: np.ndarray | None = None
        self._plan_age = 0
        self._u_prev = self.u_rest.copy()
        self._prev_obs: np.ndarray | None = None
        self._last: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.gains = np.ones(2)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Solve the NMPC problem for one observation ``(19,)``; returns the normalised action ``(8,)``."""
        obs = np.asarray(obs, dtype=np.float64)
        if obs.shape != (19,):
            raise ValueError(f"obs must have shape (19,), got {obs.shape}")
        if not np.all(np.isfinite(obs)):
            u = self._fallback()
        else:
            state, ref, vref = self._estimate(obs)
            if self._last is not None:
                before, z_applied, z_before = self._last
                end, v_mean = (np.asarray(v).ravel() for v in self._interval(before, z_applied, z_before, self.gains))
                if self.settings.adapt_rate > 0:
                    self._adapt(state)
                if self.settings.observer and np.all(np.isfinite(end)):
                    # the observation holds velocities averaged over the last period: they lag the
                    # current ones; shift the model's end-of-period velocities by the measured offset
                    state[3:6] = end[3:6] + (state[3:6] - v_mean)
            u = self._plan_step(state, ref, vref)
            self._last = (state, self._to_z(u), self._to_z(self._u_prev))
        self._prev_obs = obs.copy()
        self._u_prev = u
        return self.fins.action(u[2], u[0], u[3], u[1])

    # ------------------------------------------------------------------ internals
    def _estimate(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """State ``(6,)``, target position and target velocity (tank frame) from an observation."""
        c, s = obs[2], obs[3]
        psi = math.atan2(s, c)
        velocity = obs[4:7].copy()
        prev = self._prev_obs
        if self.velocity == "difference" and prev is not None and np.all(np.isfinite(prev)):
            psi_prev = math.atan2(prev[3], prev[2])
            dpsi = (psi - psi_prev + math.pi) % (2 * math.pi) - math.pi
            mid = psi_prev + 0.5 * dpsi
            dx, dy = (obs[0] - prev[0]) / self.dt, (obs[1] - prev[1]) / self.dt
            velocity = np.array([math.cos(mid) * dx + math.sin(mid) * dy,
                                 -math.sin(mid) * dx + math.cos(mid) * dy, dpsi / self.dt])
        state = np.array([obs[0], obs[1], psi, *velocity])
        ref = np.array([obs[0] + c * obs[7] - s * obs[8], obs[1] + s * obs[7] + c * obs[8]])
        vref = np.array([c * obs[9] - s * obs[10], s * obs[9] + c * obs[10]]) if self.track else np.zeros(2)
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
        predicted = np.asarray(self._rollout(before, plan, z_before, self.gains))[:, 1]
        turn_pred = predicted[2] - before[2]
        turn_meas = (state[2] - before[2] + math.pi) % (2 * math.pi) - math.pi
        move_pred = float(np.hypot(*(predicted[:2] - before[:2])))
        move_meas = float(np.hypot(*(state[:2] - before[:2])))
        low, high = s.gain_bounds
        if abs(turn_pred) > 0.03 and turn_pred * turn_meas > 0:
            ratio = float(np.clip(turn_meas / turn_pred, 0.5, 2.0))
            self.gains[1] = float(np.clip(self.gains[1] * ratio ** (2 * s.adapt_rate), low, high))
        if move_pred > 0.01 and move_meas > 0:
            ratio = float(np.clip(move_meas / move_pred, 0.5, 2.0))
            self.gains[0] = float(np.clip(self.gains[0] * ratio ** (2 * s.adapt_rate), low, high))

    def _fresh_guesses(self) -> list[np.ndarray]:
        """Input sequences ``(4, horizon)`` to start from without a plan: straight, turn left, turn right."""
        a_high, mid = self.u_high[0], self.bias_mid
        strong, weak = 0.6 * a_high, 0.15 * a_high
        pairs = ((strong, strong), (strong, weak), (weak, strong))  # the right fin stronger turns left
        return [np.tile(np.array([[ar], [al], [mid], [mid]]), (1, self._n)) for ar, al in pairs]

    def _solve(self, state: np.ndarray, ref: np.ndarray, vref: np.ndarray, u_guess: np.ndarray):
        """One IPOPT solve from ``u_guess`` ``(4, horizon)``; ``(cost, plan (horizon, 4))`` or ``None`` if unusable."""
        z_prev = self._to_z(self._u_prev)
        z_guess = np.clip(self._to_z(u_guess), self.z_low[:, None], self.z_high[:, None])
        x_guess = np.asarray(self._rollout(state, z_guess, z_prev, self.gains))
        x0 = np.nan_to_num(np.concatenate([z_guess.ravel(order="F"), x_guess.ravel(order="F")]))
        p = np.concatenate([state, ref, vref, z_prev, self.gains])
        sol = self._solver(x0=x0, p=p, lbx=self._lbx, ubx=self._ubx, lbg=0.0, ubg=0.0)
        status = self._solver.stats().get("return_status", "")
        self.statuses[status] = self.statuses.get(status, 0) + 1
        cost = float(sol["f"])
        z = np.asarray(sol["x"]).ravel()[: _N_U * self._n].reshape((_N_U, self._n), order="F")
        violation = float(np.max(np.abs(np.asarray(sol["g"]))))
        usable = status in _GOOD_STATUS or (status.startswith("Maximum") and violation < _FEASIBLE)
        if not (usable and math.isfinite(cost) and np.all(np.isfinite(z))):
            return None
        plan = np.clip(self._to_u(z).T, self.u_low, self.u_high)
        return cost, plan

    def _plan_step(self, state: np.ndarray, ref: np.ndarray, vref: np.ndarray) -> np.ndarray:
        """Solve from the shifted last plan (or fresh guesses if there is none or it fails); the first input."""
        start = time.perf_counter()
        best = None
        try:
            if self.plan is not None:
                shifted = np.vstack([self.plan[self._plan_age + 1:], np.repeat(self.plan[-1:], self._plan_age + 1, 0)])
                best = self._solve(state, ref, vref, shifted.T)
            idle = best is not None and float(np.mean(best[1][:, :2])) < self.settings.idle_amplitude * self.u_high[0]
            if best is None or idle:  # no plan, or a plan to stop: often a local minimum; try turning both ways
                for guess in self._fresh_guesses():
                    result = self._solve(state, ref, vref, guess)
                    if result is not None and (best is None or result[0] < best[0]):
                        best = result
        except Exception:  # noqa: BLE001 - a failed solve must never stop the fish controller
            best = None
        self.solve_times.append(time.perf_counter() - start)
        if best is None:
            self.failures += 1
            return self._fallback()
        self.plan = best[1]
        self._plan_age = 0
        return self.plan[0].copy()

    def _fallback(self) -> np.ndarray:
        """Next step of the last good plan, or the rest command once it is used up."""
        if self.plan is not None and self._plan_age + 1 < self.plan.shape[0]:
            self._plan_age += 1
            return self.plan[self._plan_age].copy()
        return self.u_rest.copy()
