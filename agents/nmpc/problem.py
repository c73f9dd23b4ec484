"""The optimisation problem of the NMPC baseline: packed layouts, CasADi NLP.

The controller is :mod:`pectoral_gym.agents.nmpc.controller`. Its settings are
:class:`pectoral_gym.agents.nmpc.settings.NMPCSettings`.

Model and inputs. The prediction model is the cycle-averaged model of
:mod:`pectoral_gym.model.symbolic` (eq. 25 with the identified scaling functions
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

Transitional strokes (optional, :attr:`NMPCSettings.transitions`). Every input change
also gives the first half-stroke of the new pattern its transitional forcing (``docs/model.md``
3.7). Where in the stroke a fin is when the command arrives is not observed, so the model applies
the expectation of that impulse over a uniform stroke phase
(:func:`pectoral_gym.model.symbolic_corrections.expected_transition_impulse_sx`), spread over the interval of the
change (after the latching delay in the first one). Exactly zero when the input does not change.

Cost (per interval ``k`` of the horizon, position ``p_k`` at its end):
``w_distance |p_k - r_k|`` (``r_k`` the goal, or for ``track`` the reference point's predicted position,
:mod:`pectoral_gym.agents.nmpc.reference`; the env's own tracking penalty), a terminal ``w_terminal |p_N - r_N|``,
a heading term ``w_heading (1 - cos(bearing of the aim point))`` (the goal, or the reference a few seconds further on),
the fin work ``energy_weight sum_fins P(gA) dt`` (the env's energy term, mean fin power of
:func:`pectoral_gym.model.symbolic.mean_fin_power_sx`), input changes ``w_change |du|^2`` (normalised by the
ranges) and a soft wall constraint ``w_wall sum max(0, margin - distance of nose/tail to wall)^2``.

Packed layouts. The model state is :mod:`pectoral_gym.model.symbolic`'s ``(X, Y, psi, vx, vy, omega)``
(``STATE_*``); the inputs of one interval are a :class:`FinInputs`; the NLP's parameter vector is a
:class:`ProblemParameters`; its decision vector is packed by :func:`pack_decision`.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import casadi as ca
import numpy as np

from pectoral_gym.agents.controllers.fin_map import FinMap
from pectoral_gym.agents.controllers.stop_band import StopBand, band_violation
from pectoral_gym.agents.nmpc.reference import reference_path
from pectoral_gym.agents.nmpc.settings import NMPCSettings
from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.symbolic import (
    STATE_POSITION,
    STATE_PSI,
    STATE_SIZE,
    STATE_VELOCITY,
    averaged_forcing_sx,
    body_rhs_sx,
    combined_yaw_oscillation_sx,
    mean_fin_power_sx,
    named_symbols,
    rk4_sx,
)
from pectoral_gym.model.symbolic_corrections import expected_transition_impulse_sx
from pectoral_gym.model.tank import wall_shortfall

__all__ = [
    "FinInputs", "AMPLITUDES", "ProblemParameters", "GAIN_THRUST", "GAIN_YAW", "NMPCProblem",
    "to_z", "to_u", "pack_decision", "identified_bias_range",
]

_AMPLITUDE_FLOOR = 1e-3  # rad: keeps sqrt(gA^2) differentiable; a 0.06 deg stroke is no stroke
# Fin forcing of one interval: force and moment on the body (f_x, f_y, tau), then the yaw-oscillation amplitude.
_FORCE, _OSCILLATION, _FORCING_SIZE = slice(0, 3), 3, 4


class FinInputs(NamedTuple):
    """The inputs of one control interval, in their packed order (a row of a plan, a column of ``Z``).

    Physical inputs ``u`` hold amplitudes [rad]; decision variables ``z`` (:func:`to_z`) hold their
    squares instead. Biases [rad] in both.
    """

    amplitude_right: Any
    amplitude_left: Any
    bias_right: Any
    bias_left: Any


_N_U = len(FinInputs._fields)
AMPLITUDES = slice(0, 2)  # the amplitude entries of a packed FinInputs (both fins)
GAIN_THRUST, GAIN_YAW = 0, 1  # entries of ProblemParameters.gain


class ProblemParameters(NamedTuple):
    """The NLP's parameter vector, packed in this order (symbols or numbers)."""

    x0: Any  # (6,) current state (X, Y, psi, vx, vy, omega)
    ref: Any  # (2 horizon,) goal or reference point at each interval end, tank frame [m] (column-major (2, horizon))
    vref: Any  # (2 horizon,) its velocity there [m/s] (zero for goal)
    z_prev: Any  # (4,) command still being latched, as decision variables
    gain: Any  # (2,) online corrections of the thrust and the yaw moment


def _parameter_sizes(horizon: int) -> ProblemParameters:
    return ProblemParameters(x0=STATE_SIZE, ref=2 * horizon, vref=2 * horizon, z_prev=_N_U, gain=2)


def to_z(u: np.ndarray) -> np.ndarray:
    """Physical inputs (amplitudes, biases) -> decision variables (squared amplitudes, biases)."""
    z = np.array(u, dtype=np.float64, copy=True)
    z[AMPLITUDES] = np.maximum(z[AMPLITUDES], _AMPLITUDE_FLOOR) ** 2
    return z


def to_u(z: np.ndarray) -> np.ndarray:
    """Decision variables -> physical inputs."""
    u = np.array(z, dtype=np.float64, copy=True)
    u[AMPLITUDES] = np.sqrt(np.maximum(u[AMPLITUDES], 0.0))
    return u


def pack_decision(z: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The NLP's decision vector from inputs ``z (4, horizon)`` and states ``x (6, horizon + 1)`` (column-major)."""
    return np.concatenate([np.ravel(z, order="F"), np.ravel(x, order="F")])


_TRACK_HEADING_LOOKAHEAD = 5.0  # s
_TRACK_HEADING_SCALE = 0.001  # m


def _auto(value: float | None, task: str, goal: float, track: float) -> float:
    """A setting's value: ``value``, or when it is ``None`` the task's default."""
    if value is not None:
        return float(value)
    return track if task == "track" else goal


def _nlp_solver(nlp: dict[str, Any], s: NMPCSettings) -> ca.Function:
    """The CasADi ``nlpsol`` of :attr:`NMPCSettings.solver` for an SX NLP (SX functions: ``expand`` adds nothing)."""
    common = {"print_time": False, "error_on_fail": False, "show_eval_warnings": False}  # NaN at rejected trial
    if s.solver == "sqp":  # points is handled by the line search
        quiet = {"print_iter": False, "print_header": False, "print_info": False, "error_on_fail": False}
        extra = {}
        if s.hessian == "cost":  # the objective's Hessian only: no curvature of the model (Gauss-Newton-like)
            x, lam_f, lam_g = nlp["x"], ca.SX.sym("lam_f"), ca.SX.sym("lam_g", nlp["g"].shape[0])
            hess, _ = ca.hessian(nlp["f"], x)
            extra["hess_lag"] = ca.Function("nlp_hess_l", [x, nlp["p"], lam_f, lam_g], [lam_f * hess],
                                            ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
        return ca.nlpsol("nmpc", "sqpmethod", nlp, {
            **common, "qpsol": "qrqp", "qpsol_options": quiet, "max_iter": int(s.max_iter),
            "convexify_strategy": "regularize", "print_header": False, "print_iteration": False,
            "print_status": False, "tol_pr": 1e-6, "tol_du": 1e-4, **extra})
    return ca.nlpsol("nmpc", "ipopt", nlp, {**common, "ipopt": {
        "print_level": 0, "sb": "yes", "max_iter": int(s.max_iter), "max_cpu_time": float(s.max_cpu_time),
        "tol": 1e-5, "acceptable_tol": 1e-3, "acceptable_iter": 5, "mu_strategy": "adaptive"}})


def identified_bias_range(bias_range: tuple[float, float], scaling: ScalingFunctions | None) -> tuple[float, float]:
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


class NMPCProblem:
    """The NLP of the NMPC baseline, built once, parametric in a :class:`ProblemParameters`.

    Args:
        config: The environment settings (control period, parameters, ranges, task).
        settings: The NMPC settings.
        fins: The action codec (fixed period and ratio).
        scaling: Scaling functions of the prediction model, or ``None`` for K = 1.
        z_low: Lower bounds of the decision variables of one interval ``(4,)``.
        z_high: Their upper bounds.

    Attributes:
        solver: The CasADi ``nlpsol`` (IPOPT or SQP, :attr:`NMPCSettings.solver`).
        rollout: ``(x0, Z, z_prev, gain) -> X (6, horizon + 1)``, the model's trajectory under the
            per-interval inputs ``Z (4, horizon)``.
        cost: ``(decision, parameters) -> cost``, the NLP's objective (screens candidate plans).
        state_cost: ``(X (6, horizon + 1), parameters) -> cost``, the objective's terms of the states alone
            (distance, heading, reach, walls): prices trajectories rolled out elsewhere
            (:mod:`pectoral_gym.agents.nmpc.spin`).
        energy_weight: Weight of the fin work [1/J].
        energy_rate: ``energy_weight`` x mean fin power per cubed amplitude: the objective's energy term
            of one fin is ``energy_rate gA^3 dt``.
        input_width: Scale of each input entry (``z``) in the input-change term ``w_change |dz / width|^2``.
        stop_band: The :class:`pectoral_gym.agents.controllers.stop_band.StopBand` of the wall terms, or ``None`` (nose
            and tail ``wall_margin`` from the walls).
        interval: ``(x0, z_applied, z_prev, gain) -> (end state, mean body velocities)`` over one
            control period (trapezoid over the RK4 steps).
        lbx, ubx: Bounds of the decision vector.
        horizon: Number of control intervals.
        block_of: ``(horizon,)`` index of the planned input (block) acting in each interval.
        n_blocks: Number of planned inputs (columns of the decision's input part).
        n_delay_steps: RK4 steps of the first interval under the previous command.
    """

    def __init__(self, config: EnvConfig, settings: NMPCSettings, fins: FinMap, scaling: ScalingFunctions | None,
                 z_low: np.ndarray, z_high: np.ndarray):
        s, params = settings, config.params
        dt = config.control_period
        n, m = int(s.horizon), int(s.substeps)
        h = dt / m
        zeta, period = fins.ratio, fins.period
        delay = s.latch_delay if s.latch_delay is not None else (zeta**2 + 1) * period / (2 * (zeta + 1) ** 2)
        n_delay = min(m, int(round(delay / h)))
        blocks = tuple(int(b) for b in s.blocks) if s.blocks is not None else (1,) * n
        block_of = np.repeat(np.arange(len(blocks)), blocks)
        nb = len(blocks)

        # Inputs: squared amplitudes (thrust ~ gA J1(gA) ~ gA^2 / 2 has a non-zero gradient at rest in
        # gA^2, not in gA) and biases. The forcing is constant over an interval: computed once per interval.
        u_sym = ca.SX.sym("u", _N_U)
        u = FinInputs(*(u_sym[i] for i in range(_N_U)))
        beat_r = ca.vertcat(u.bias_right, ca.sqrt(u.amplitude_right), period, zeta)
        beat_l = ca.vertcat(u.bias_left, ca.sqrt(u.amplitude_left), period, zeta)
        right = averaged_forcing_sx(beat_r, 1.0, params, scaling)
        left = averaged_forcing_sx(beat_l, -1.0, params, scaling)
        oscillation = combined_yaw_oscillation_sx(beat_r, beat_l, scaling)  # equal periods: fins beat in phase
        oscillating = oscillation is not None
        oscillation = oscillation if oscillating else 0.0
        forcing = ca.Function("forcing", [u_sym], [ca.vertcat(right + left, oscillation)])
        # Expected impulse of the transitional strokes of a change u_from -> u (both fins), as a forcing vector.
        u_from = ca.SX.sym("u_from", _N_U)
        v = FinInputs(*(u_from[i] for i in range(_N_U)))
        from_r = ca.vertcat(v.bias_right, ca.sqrt(v.amplitude_right), period, zeta)
        from_l = ca.vertcat(v.bias_left, ca.sqrt(v.amplitude_left), period, zeta)
        impulse = (expected_transition_impulse_sx(from_r, beat_r, 1.0, params)
                   + expected_transition_impulse_sx(from_l, beat_l, -1.0, params))
        if not (fins.spec.transitions if s.transitions is None else s.transitions):  # None: the planning model's
            impulse = ca.DM.zeros(3)
        transition = ca.Function("transition", [u_from, u_sym], [ca.vertcat(impulse, 0.0)])
        x = ca.SX.sym("x", STATE_SIZE)
        f = ca.SX.sym("f", _FORCING_SIZE)
        rhs = ca.Function("rhs", [x, f], [
            body_rhs_sx(x, f[_FORCE], params, s.smoothing, f[_OSCILLATION] if oscillating else None)])
        step = ca.Function("rk4", [x, f], [rk4_sx(rhs, x, f, h)])

        power_per_cubed_amplitude = mean_fin_power_sx(1.0, period, zeta, params)  # P(gA) = P(1) gA^3
        energy_weight = config.energy_weight if s.energy_weight is None else s.energy_weight
        width = np.where(z_high > z_low, z_high - z_low, 1.0)
        half = 0.5 * params.body_length
        band = StopBand.from_params(params, s.stop_band) if s.stop_band is not None else None
        turn_radius = float(s.turn_radius)
        distance_scale = s.distance_scale
        if distance_scale is None:
            distance_scale = 0.05 if config.task == "track" else 1e-3

        p = named_symbols(_parameter_sizes(n))
        ref_k, vref_k = ca.reshape(p.ref, 2, n), ca.reshape(p.vref, 2, n)
        lookahead = _auto(s.heading_lookahead, config.task, goal=0.0, track=_TRACK_HEADING_LOOKAHEAD)
        heading_scale = _auto(s.heading_scale, config.task, goal=0.05, track=_TRACK_HEADING_SCALE)
        Z = ca.SX.sym("Z", _N_U, nb)
        X = ca.SX.sym("X", STATE_SIZE, n + 1)
        Z_roll = ca.SX.sym("Z_roll", _N_U, n)
        thrust, yaw = p.gain[GAIN_THRUST], p.gain[GAIN_YAW]
        gains = ca.vertcat(thrust, thrust, yaw, 1.0)  # on (f_x, f_y, tau); the yaw-oscillation amplitude is not scaled
        f_prev = gains * forcing(p.z_prev)
        g = [X[:, 0] - p.x0]
        x_roll = [p.x0]
        cost_x, cost_u = 0.0, 0.0  # the terms of the states and of the inputs (the spin candidates price them apart)
        f_blocks = [gains * forcing(Z[:, b]) for b in range(nb)]  # once per block: the costly part
        after = [j for j in range(m) if j >= n_delay] or list(range(m))  # first interval's substeps after the latch
        spread = [len(after) * h] + [m * h] * (n - 1)  # each interval's transitional impulse acts over this time
        for k in range(n):
            f_k, f_roll = f_blocks[block_of[k]], gains * forcing(Z_roll[:, k])
            change = k == 0 or block_of[k - 1] != block_of[k]
            t_k = gains * transition(p.z_prev if k == 0 else Z[:, block_of[k - 1]], Z[:, block_of[k]]) / spread[k] \
                if change else 0.0
            t_roll = gains * transition(p.z_prev if k == 0 else Z_roll[:, k - 1], Z_roll[:, k]) / spread[k]
            xk, rk = X[:, k], x_roll[-1]
            for j in range(m):
                delayed = k == 0 and j < n_delay
                active = k > 0 or j in after
                xk = step(xk, f_prev if delayed else (f_k + t_k if active else f_k))
                rk = step(rk, f_prev if delayed else (f_roll + t_roll if active else f_roll))
            g.append(X[:, k + 1] - xk)
            x_roll.append(rk)
            pos, psi = X[STATE_POSITION, k + 1], X[STATE_PSI, k + 1]
            error = ref_k[:, k] - pos
            dist = ca.sqrt(ca.sumsqr(error) + distance_scale**2)
            cost_x += s.w_distance * dist
            if k == n - 1:
                cost_x += s.w_terminal * dist
                # A target closer than 2 R |sin e| lies inside a turning circle of radius R and cannot be
                # reached by turning towards it (d^2 < 2 R |y_body|); end the horizon where it can.
                lateral = -ca.sin(psi) * error[0] + ca.cos(psi) * error[1]
                inside = 2.0 * turn_radius * ca.sqrt(lateral**2 + 1e-6) - ca.sumsqr(error)
                cost_x += s.w_reach * ca.fmax(0.0, inside) / turn_radius
            # 1 - cos(bearing of the target): turns the fish towards a target behind it, which a
            # distance cost over a short horizon cannot (turning first moves the fish away)
            # (track: towards the reference point ``heading_lookahead`` seconds further along its path)
            aim = error + lookahead * vref_k[:, k] if lookahead > 0 else error
            facing = (ca.cos(psi) * aim[0] + ca.sin(psi) * aim[1]) / ca.sqrt(ca.sumsqr(aim) + heading_scale**2)
            cost_x += s.w_heading * (1.0 - facing)
            b = int(block_of[k])
            z_k = FinInputs(*(Z[i, b] for i in range(_N_U)))
            cost_u += energy_weight * power_per_cubed_amplitude * (
                z_k.amplitude_right ** 1.5 + z_k.amplitude_left ** 1.5) * dt  # gA^3 = (gA^2)^1.5
            if k == 0 or block_of[k - 1] != b:  # an input change at the start of a block
                prev = p.z_prev if b == 0 else Z[:, b - 1]
                cost_u += s.w_change * ca.sumsqr((Z[:, b] - prev) / width)
            if band is not None:  # the robot's stopping-distance band, whole outline
                cost_x += s.w_wall * band_violation(X[0, k + 1], X[1, k + 1], psi, X[3, k + 1], X[4, k + 1], band, ca)
            else:
                cost_x = wall_shortfall(X[0, k + 1], X[1, k + 1], ca.cos(psi), ca.sin(psi), half, s.wall_margin, ca,
                                        total=cost_x, weight=s.w_wall)  # nose and tail
        cost = cost_x + cost_u
        nlp = {"x": ca.vertcat(ca.vec(Z), ca.vec(X)), "f": cost, "g": ca.vertcat(*g), "p": ca.vertcat(*p)}
        self.solver = _nlp_solver(nlp, s)
        self.horizon = n
        self.dt = dt
        self.block_of = block_of
        self.n_blocks = nb
        # State bounds keep trial points of the solver where RK4 stays finite (physical values are far inside).
        x_bound = np.tile([np.inf, np.inf, np.inf, 1.0, 1.0, 3.0], n + 1)
        self.lbx = pack_decision(np.tile(z_low, nb), -x_bound)
        self.ubx = pack_decision(np.tile(z_high, nb), x_bound)
        self.rollout = ca.Function("rollout", [p.x0, Z_roll, p.z_prev, p.gain], [ca.horzcat(*x_roll)])
        self.cost = ca.Function("cost", [nlp["x"], nlp["p"]], [cost])
        self.state_cost = ca.Function("state_cost", [X, nlp["p"]], [cost_x])
        self.stop_band = band
        self.energy_weight = float(energy_weight)
        self.energy_rate = float(energy_weight * power_per_cubed_amplitude)  # cost per s of (gA / rad)^3 of one fin
        self.input_width = width  # the scale of the input-change term, per z entry
        # One interval from x0 under the applied command: end state and mean body velocities (trapezoid).
        z_applied = ca.SX.sym("z_applied", _N_U)
        xk, f_applied = p.x0, gains * forcing(z_applied)
        t_applied = gains * transition(p.z_prev, z_applied) / spread[0]
        v_sum = 0.5 * p.x0[STATE_VELOCITY]
        for j in range(m):
            xk = step(xk, f_prev if j < n_delay else (f_applied + t_applied if j in after else f_applied))
            v_sum += xk[STATE_VELOCITY] if j < m - 1 else 0.5 * xk[STATE_VELOCITY]
        self.interval = ca.Function("interval", [p.x0, z_applied, p.z_prev, p.gain], [xk, v_sum / m])
        self.n_delay_steps = n_delay

    def inputs(self, decision: np.ndarray) -> np.ndarray:
        """The per-interval inputs ``Z (4, horizon)`` of a decision vector (its blocks repeated)."""
        z = np.asarray(decision).ravel()[: _N_U * self.n_blocks].reshape((_N_U, self.n_blocks), order="F")
        return z[:, self.block_of]

    def blocked(self, z: np.ndarray) -> np.ndarray:
        """Per-interval inputs ``(4, horizon)`` -> planned inputs ``(4, n_blocks)`` (each block's first interval)."""
        starts = np.flatnonzero(np.r_[True, np.diff(self.block_of) != 0])
        return np.asarray(z)[:, starts]

    def parameters(self, x0: np.ndarray, ref: np.ndarray, vref: np.ndarray, z_prev: np.ndarray,
                   gain: np.ndarray, path: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """The packed parameter vector (the order of :class:`ProblemParameters`).

        ``ref``, ``vref``: the target's position and velocity now. ``path``: its predicted positions and
        velocities ``(2, horizon)`` at the interval ends
        (:class:`pectoral_gym.agents.nmpc.reference.ReferencePredictor`); ``None``: straight on with ``vref`` (a goal,
        ``vref = 0``, stays put).
        """
        path, velocity = path if path is not None else reference_path(ref, vref, 0.0, self.dt, self.horizon)
        return np.concatenate([np.ravel(v, order="F") for v in ProblemParameters(x0, path, velocity, z_prev, gain)])
