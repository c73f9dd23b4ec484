"""Per-pattern NMPC of the paper's Sec. 4.3: the scaling values as inputs of the averaged model.

For one fin pattern, the averaged body dynamics with the scaling values as
inputs ``u = (K_fx, K_fy, K_m)`` are (eqs. 30-32; like eq. 19 the forcing is
divided by ``m1, m2, J3``, which the paper's typesetting drops)::

    d vx / dt    = f1(v) + u1 fx_avg / m1
    d vy / dt    = f2(v) + u2 fy_avg / m2
    d omega / dt = f3(v) + u3 tau_avg / J3

(with the ``"base"`` sway convention of ``pectoral_gym.model.kfunctions``, ``fy_avg``
is replaced by ``base = fx_avg / sin(bias)``: the solver is the same, only the
forcing vector it is given differs).

With the oscillation-averaged yaw damping (``pectoral_gym.model.averaging``, beyond
the paper) ``f3`` uses ``c4 A^2 q(omega / A)`` instead of ``c4 omega|omega|``, with
the pattern's yaw-oscillation amplitude ``A`` measured in its reference run;
``A = 0`` gives the paper's ``f3``.

The NMPC drives the tracking error ``e = v - v_ref`` (eq. 33) to zero by
minimising ``sum_k e_k' Q e_k ts + e_N' Q_T e_N`` (eqs. 34-35) over a horizon
``T`` sampled every ``ts``, with ``u`` piecewise constant per sample. The
initial state is the reference itself, so the optimal inputs are constant and
satisfy the averaged equations at ``v_ref`` algebraically (paper-notes)::

    K_i = -f_i(v_ref) / forcing_i

:func:`algebraic_scaling` computes that oracle; :class:`ScalingNmpc` solves
the NMPC (one CasADi/IPOPT problem built once, parametric in the pattern) and
reports how far each solution is from the oracle.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, NamedTuple

import casadi as ca
import numpy as np

from pectoral_gym.model.averaging import EXACT, averaged_body_accel, averaged_fin_forcing
from pectoral_gym.model.dynamics import linearised_rate
from pectoral_gym.model.kfunctions import UNIT_K, ScalingFunctions
from pectoral_gym.model.params import FishParams, body_coefficients, coefficient_vector
from pectoral_gym.model.symbolic import OSCILLATION_FLOOR, body_accel_sx, named_symbols, rk4_sx

__all__ = ["RK4_STEP_RATE", "IdentificationNmpcSettings", "NmpcResult", "ScalingNmpc", "algebraic_scaling",
           "auto_substeps", "unscaled_forcing"]

_UNIT_BASE_K = ScalingFunctions(UNIT_K.powers, UNIT_K.coefs, sway="base")
#: Largest ``h * rate`` of the NMPC's RK4 steps: 72 % of RK4's real stability limit (2.785).
RK4_STEP_RATE = 2.0


class _Parameters(NamedTuple):
    """The parameter vector of the NLP, packed in this order (symbols or numbers)."""

    v0: Any  # (3,) initial (vx, vy, omega)
    v_ref: Any  # (3,) reference (vx, vy, omega), eq. (33)
    forcing: Any  # (3,) unscaled averaged forcing of the pattern
    oscillation: Any  # (1,) yaw-oscillation amplitude [rad/s]


@dataclass(frozen=True)
class IdentificationNmpcSettings:
    """Settings of the scaling NMPC (defaults: the paper's Sec. 4.3).

    Attributes:
        horizon: Prediction horizon ``T`` [s].
        sampling: Sampling interval ``t_s`` [s]; ``u`` is constant over each.
        q: Stage weight, ``Q = q I3`` (eq. 34).
        q_terminal: Terminal weight, ``Q_T = q_terminal I3`` (eq. 35).
        substeps: RK4 steps per sampling interval; 0 chooses them from the
            fastest linearised time constant over the patterns.
        tol: IPOPT convergence tolerance.
        max_iter: IPOPT iteration limit.
    """

    horizon: float = 10.0
    sampling: float = 1.0
    q: float = 2000.0
    q_terminal: float = 80.0
    substeps: int = 0
    tol: float = 1e-12
    max_iter: int = 100

    def __post_init__(self) -> None:
        if not (self.horizon > 0 and self.sampling > 0 and self.horizon >= self.sampling):
            raise ValueError(f"need horizon >= sampling > 0, got horizon={self.horizon}, sampling={self.sampling}")
        if not (self.q > 0 and self.q_terminal >= 0):
            raise ValueError(f"need q > 0 and q_terminal >= 0, got {self.q}, {self.q_terminal}")
        if self.substeps < 0 or self.max_iter < 1 or not self.tol > 0:
            raise ValueError("substeps must be >= 0, max_iter >= 1 and tol > 0")

    @property
    def samples(self) -> int:
        """Number of sampling intervals over the horizon."""
        return max(1, round(self.horizon / self.sampling))

    def as_dict(self) -> dict:
        """Plain dict (JSON-ready)."""
        return asdict(self)


@dataclass(frozen=True)
class NmpcResult:
    """NMPC solution for one pattern.

    Attributes:
        k: ``(3,)`` optimal inputs ``(K_fx, K_fy, K_m)`` of the first sample.
        spread: Largest difference between the inputs of any two samples (0 for constant inputs).
        success: Whether IPOPT reported success.
        status: IPOPT's return status.
        cost: Optimal cost.
    """

    k: np.ndarray
    spread: float
    success: bool
    status: str
    cost: float


def unscaled_forcing(patterns: np.ndarray, params: FishParams, sway: str = "paper") -> np.ndarray:
    """``(n, 3)`` forcing terms the scaling values multiply, right fin (eq. 25, exact averages of paper-notes).

    With ``sway="paper"``: ``(fx_avg, fy_avg, tau_avg)`` with K = 1. With
    ``sway="base"`` the middle column is ``base = fx_avg / sin(bias)``, the
    term ``K_fy`` multiplies in ``"base"`` coefficient files (``pectoral_gym.model.kfunctions``).
    """
    if sway not in ("paper", "base"):
        raise ValueError(f"sway must be 'paper' or 'base', got {sway!r}")
    coef = coefficient_vector(params)
    arrays = (UNIT_K if sway == "paper" else _UNIT_BASE_K).kernel_arrays()
    return np.array([averaged_fin_forcing(*p, 1.0, coef, EXACT, arrays) for p in patterns]).reshape(-1, 3)


def algebraic_scaling(
    velocities: np.ndarray, forcing: np.ndarray, params: FishParams, oscillation: np.ndarray | None = None
) -> np.ndarray:
    """The oracle ``K_i = -f_i(v_ref) / forcing_i`` (per unit mass), ``(n, 3)``; NaN where the forcing is 0.

    ``oscillation``: ``(n,)`` yaw-oscillation amplitudes [rad/s] for the
    oscillation-averaged yaw damping; ``None`` for the paper's damping.
    """
    body = body_coefficients(params)
    masses = np.array([body.m1, body.m2, body.J3])
    amplitude = np.zeros(len(velocities)) if oscillation is None else np.asarray(oscillation, dtype=np.float64)
    drift = np.array([averaged_body_accel(*v, 0.0, 0.0, 0.0, *body, a)
                      for v, a in zip(velocities, amplitude, strict=True)]).reshape(-1, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(forcing != 0.0, -drift * masses / forcing, np.nan)


def auto_substeps(
    velocities: np.ndarray, params: FishParams, sampling: float, oscillation: np.ndarray | None = None
) -> int:
    """RK4 steps per sampling interval for the fastest linearised rate over the patterns' velocities.

    The rate is :func:`pectoral_gym.model.dynamics.linearised_rate` (a bound on the Jacobian of eqs. 19-20,
    the averaged model's step rule too). The steps keep ``h * rate <=`` :data:`RK4_STEP_RATE`, inside RK4's
    real stability interval (``h * rate <= 2.785``) with a margin. Accuracy of transients needs no more:
    the NMPC starts at the reference, and its optimum (constant inputs that make ``v_ref`` an equilibrium)
    is an equilibrium of any RK4 step (all four stages vanish), so the solution does not depend on ``h``;
    only the solver's path to it does, which a stable step keeps near the reference.
    """
    velocities = np.asarray(velocities, dtype=np.float64).reshape(-1, 3)
    amplitude = np.zeros(len(velocities)) if oscillation is None else np.asarray(oscillation, dtype=np.float64)
    b = body_coefficients(params)
    rates = [linearised_rate(math.hypot(vx, vy), abs(w), float(a), b.m1, b.m2, b.J3, b.c1, b.c2, b.c4)
             for (vx, vy, w), a in zip(velocities, amplitude, strict=True)]
    return max(4, math.ceil(sampling * max([1.0, *rates]) / RK4_STEP_RATE))


class ScalingNmpc:
    """The NMPC problem (30)-(35), built once and solved per pattern.

    Args:
        params: Model parameters.
        settings: NMPC settings.
        velocities: Reference velocities of all patterns to be solved (to pick the RK4 substeps).
        oscillation: Their yaw-oscillation amplitudes [rad/s] ``(n,)`` (oscillation-averaged yaw
            damping), or ``None`` for the paper's damping.
    """

    def __init__(self, params: FishParams, settings: IdentificationNmpcSettings, velocities: np.ndarray,
                 oscillation: np.ndarray | None = None):
        self.params = params
        self.settings = settings
        n_samples = settings.samples
        self.substeps = settings.substeps or auto_substeps(
            np.asarray(velocities), params, settings.sampling, oscillation)
        v = ca.SX.sym("v", 3)
        u = ca.SX.sym("u", 3)
        forcing = ca.SX.sym("forcing", 3)
        self._sizes = _Parameters(v0=3, v_ref=3, forcing=3, oscillation=1)
        amplitude = ca.SX.sym("A", 1)

        def rhs(state, inputs):
            k, f, a = inputs  # eqs. (30)-(32): the scaling values multiply the forcing
            return body_accel_sx(state, k * f, params, yaw_oscillation=ca.fmax(a, OSCILLATION_FLOOR))

        end = rk4_sx(rhs, v, (u, forcing, amplitude), settings.sampling / self.substeps, self.substeps)
        step = ca.Function("step", [v, u, forcing, amplitude], [end])  # one sampling interval

        inputs = ca.SX.sym("K", 3, n_samples)  # column k: u over sample k
        p = named_symbols(self._sizes)
        cost = 0.0
        x = p.v0
        for k in range(n_samples):
            x = step(x, inputs[:, k], p.forcing, p.oscillation)
            e = x - p.v_ref  # eq. (33)
            cost += settings.q * settings.sampling * ca.dot(e, e)  # eq. (34), stage cost at the sample
        cost += settings.q_terminal * ca.dot(x - p.v_ref, x - p.v_ref)  # eq. (35)
        nlp = {"x": ca.vec(inputs), "p": ca.vertcat(*p), "f": cost}
        opts = {
            "ipopt.print_level": 0,
            "print_time": False,
            "ipopt.sb": "yes",
            "ipopt.tol": settings.tol,
            "ipopt.max_iter": settings.max_iter,
            "ipopt.hessian_approximation": "exact",
        }
        self._solver = ca.nlpsol("scaling_nmpc", "ipopt", nlp, opts)
        self._n_samples = n_samples

    def solve(self, v_ref: np.ndarray, forcing: np.ndarray, guess: np.ndarray | None = None,
              oscillation: float | np.ndarray = 0.0) -> NmpcResult:
        """Optimal inputs for one pattern, starting at ``v_ref``.

        Args:
            v_ref: ``(3,)`` reference ``(vx, vy, omega)`` from the full model.
            forcing: ``(3,)`` unscaled averaged forcing of the pattern.
            guess: Initial guess of ``K`` (3,) (e.g. the previous pattern's solution); ones if ``None``.
            oscillation: The pattern's yaw-oscillation amplitude [rad/s] (0 for the paper's damping).

        A solver failure is returned as ``success=False`` (never raised).
        """
        guess = np.ones(3) if guess is None else np.asarray(guess, dtype=np.float64)
        x0 = np.tile(np.where(np.isfinite(guess), guess, 1.0), self._n_samples)
        p = np.concatenate([np.ravel(x) for x in _Parameters(v_ref, v_ref, forcing, oscillation)])
        try:
            sol = self._solver(x0=x0, p=p)
            stats = self._solver.stats()
            inputs = np.array(sol["x"]).reshape(self._n_samples, 3)  # ca.vec stacks the columns: row k = sample k
            return NmpcResult(
                k=inputs[0].copy(),
                spread=float(np.max(np.ptp(inputs, axis=0))),
                success=bool(stats["success"]),
                status=str(stats["return_status"]),
                cost=float(sol["f"]),
            )
        except RuntimeError as err:  # CasADi raises on evaluation errors (NaN, ...)
            return NmpcResult(np.full(3, np.nan), math.nan, False, f"error: {err}", math.nan)
