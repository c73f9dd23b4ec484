"""How the averaged model's steady state answers the scaling values K (eqs. 19-20, 29).

:func:`predicted_turning` solves for the steady state under given K (the
held-out comparison of :mod:`pectoral_gym.scaling.identification.identify`); :func:`sensitivity_weights`
linearises it to weigh K errors by the velocity errors they cause (the fit
weights of :mod:`pectoral_gym.scaling.identification.regression`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import optimize

from pectoral_gym.model.averaging import averaged_body_accel
from pectoral_gym.model.params import FishParams, body_coefficients

__all__ = ["predicted_turning", "sensitivity_weights"]


def predicted_turning(velocities: np.ndarray, forcing: np.ndarray, k: np.ndarray, params: FishParams,
                      oscillation: np.ndarray | None = None) -> np.ndarray:
    """``(n, 2)`` turning radius and period of the averaged model's steady state under scaling values ``k``.

    The equilibrium of eqs. (19)-(20) with the scaled forcing ``k * forcing``
    (and the yaw-oscillation amplitudes ``oscillation`` of the
    oscillation-averaged damping, ``None`` for the paper's) is found by a root
    solve started at the full model's steady state ``velocities`` (so on the
    same turning branch). NaN where it fails or the fish does not turn.
    """
    body = body_coefficients(params)
    masses = np.array([body.m1, body.m2, body.J3])
    amplitude = np.zeros(len(velocities)) if oscillation is None else np.asarray(oscillation, dtype=np.float64)
    out = np.full((len(velocities), 2), np.nan)
    for i, (v0, f) in enumerate(zip(velocities, k * forcing, strict=True)):
        if not (np.all(np.isfinite(v0)) and np.all(np.isfinite(f))):
            continue
        sol = optimize.root(lambda v, f=f, a=amplitude[i]: averaged_body_accel(*v, *f, *body, a), v0,
                            method="hybr", tol=1e-12)
        # hybr can stop with "no further improvement" at a converged point; judge by the residual instead
        residual = np.max(np.abs(sol.fun) / (np.abs(f) / masses + 1e-300))
        if residual < 1e-8 and abs(sol.x[2]) > 0:
            out[i] = math.hypot(sol.x[0], sol.x[1]) / abs(sol.x[2]), 2.0 * math.pi / abs(sol.x[2])
    return out


def sensitivity_weights(
    velocities: np.ndarray, forcing: np.ndarray, params: FishParams, floor: float = 1e-3, coupled: bool = False,
    oscillation: np.ndarray | None = None,
) -> np.ndarray:
    """``(n, 3)`` relative error of speed or yaw rate per unit error in ``(K_fx, K_fy, K_m)``.

    Linearising eqs. (19)-(20) about the steady state ``v``: an error ``dK_j``
    adds ``dK_j forcing_j / m_j`` to component ``j`` of the acceleration and
    moves the steady state by ``dv = -A^-1 e_j dK_j forcing_j / m_j``, ``A`` the
    Jacobian of the body dynamics (by central differences; it includes the
    Munk moment ``(m1 - m2) vx vy / J3``, which makes the yaw rate very
    sensitive where the fin moment is small). The weight is the larger of the
    relative changes of the speed and of the yaw rate, the quantities the
    turning radius and period (eq. 29) are made of. ``floor`` [m/s, rad/s]
    keeps the weights finite near rest.

    With ``coupled=False`` (default) only the diagonal of ``A`` is kept (each
    K acts on its own velocity component through that component's damping);
    the coupled weights are very large wherever the Munk moment nearly
    balances the yaw damping, and fits weighted by them validated worse
    (docs/scaling.md). ``oscillation``: per-pattern yaw-oscillation amplitudes
    [rad/s] of the oscillation-averaged yaw damping (``None``: the paper's).
    """
    velocities = np.asarray(velocities, dtype=np.float64)
    body = body_coefficients(params)
    masses = np.array([body.m1, body.m2, body.J3])
    weights = np.empty((len(velocities), 3))
    amplitude = np.zeros(len(velocities)) if oscillation is None else np.asarray(oscillation, dtype=np.float64)
    for i, v in enumerate(velocities):
        jac = np.empty((3, 3))
        for k in range(3):
            h = 1e-7 * max(abs(v[k]), floor)
            up, down = v.copy(), v.copy()
            up[k] += h
            down[k] -= h
            plus = averaged_body_accel(*up, 0.0, 0.0, 0.0, *body, amplitude[i])
            minus = averaged_body_accel(*down, 0.0, 0.0, 0.0, *body, amplitude[i])
            jac[:, k] = (np.array(plus) - np.array(minus)) / (2 * h)
        if not coupled:
            jac = np.diag(np.diag(jac))
        try:
            response = -np.linalg.solve(jac, np.diag(np.asarray(forcing[i]) / masses))  # column j: dv per unit dK_j
        except np.linalg.LinAlgError:
            response = np.full((3, 3), np.inf)
        speed = max(math.hypot(v[0], v[1]), floor)
        d_speed = (v[0] * response[0] + v[1] * response[1]) / speed**2
        d_omega = response[2] / max(abs(v[2]), floor)
        weights[i] = np.maximum(np.abs(d_speed), np.abs(d_omega))
    return np.minimum(weights, 1e6)
