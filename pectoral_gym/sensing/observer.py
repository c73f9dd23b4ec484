"""The high-gain observer of (X, Y, psi) as batched numba kernels: one implementation for the sim and the robot.

For each measured coordinate ``y`` in (X, Y, psi) a second-order high-gain observer (paper Sec. 4.1)

    x1' = x2 + (a1 / eps) (y - x1)
    x2' = (a2 / eps^2) (y - x1)

estimates the coordinate (x1) and its rate (x2). Seen from the true rate to ``x2`` it is the second-order
low-pass ``G(s) = wn^2 / (s^2 + 2 zeta wn s + wn^2)`` with ``wn = sqrt(a2) / eps`` and
``zeta = a1 / (2 sqrt(a2))`` (:func:`frequency_response`). Measurements arrive at irregular times; between two of
them the measurement is interpolated linearly (first-order hold) and the linear system ``z' = A z + b u``,
``z = (x1, x2)``, is integrated exactly (:func:`transition`: ``exp(A h)`` of the 2x2 matrix in closed form), so a
ramp is followed without error at any spacing. Heading is unwrapped against the observer's own prediction, so
a measurement jumping from +pi to -pi is a small turn, not a full one. A gap longer than ``max_gap`` restarts
the observer at rest at the new pose. The output is the simulated state layout ``X, Y, psi (unwrapped), vx, vy,
omega``, the world rates rotated into the body frame (eq. 19's kinematics, inverted).

Every kernel works on row ``i`` of batched arrays, so ``n`` observers (the simulated envs' cameras,
:mod:`pectoral_gym.envs.sensed`) and the robot's one
(:class:`pectoral_gym.hardware.vision.observer.HighGainObserver`, ``n = 1``) run the same arithmetic:

* ``z`` ``(n, 2, 3)``: rows ``x1, x2``, columns ``X, Y, psi`` (unwrapped);
* ``last`` ``(n, 4)``: time of the last measurement [s] (NaN before the first), then that measurement
  ``X, Y, psi`` (psi unwrapped);
* ``estimate`` ``(n, 6)``: the latest output.

Inputs are not checked here (the callers do: finite values, increasing times).
"""

from __future__ import annotations

import math

import numpy as np

from pectoral_gym.model.jit import njit

__all__ = ["A1", "A2", "PREDICT_AFTER_FRAMES", "frequency_response", "observer_output", "observer_predict",
           "observer_reset", "observer_update", "transition", "transition_matrices"]

#: At the end of a control period the robot env observes the observer's estimate at the last frame, or, when that
#: frame is older than this many frame periods, the estimate extrapolated to the period's end
#: (:func:`observer_predict`) (``HardwareFishEnv.step``; the simulated camera, :mod:`pectoral_gym.envs.sensed`).
PREDICT_AFTER_FRAMES = 2.0
#: The default gains ``a1, a2``: critically damped, both poles at ``-1 / eps``.
A1, A2 = 2.0, 1.0


@njit
def transition(epsilon, a1, a2, h):
    """Exact discretisation over ``h`` [s] with the measurement interpolated linearly from ``u0`` to ``u1``.

    ``z(h) = Phi z(0) + g1 u1 - gs (u1 - u0) / h`` with ``Phi = exp(A h)``, ``g1 = A^-1 (Phi - I) b``,
    ``gs = A^-1 (h Phi - A^-1 (Phi - I)) b``, ``A = [[-a1/eps, 1], [-a2/eps^2, 0]]``, ``b = (a1/eps, a2/eps^2)``.
    ``exp(A h) = e^(m h) [C I + S (A - m I)]`` with ``m = tr A / 2``, ``q^2 = m^2 - det A``, ``C = cosh(q h)``,
    ``S = sinh(q h) / q`` (``cos``/``sin`` of ``|q| h`` for complex ``q``, a series near ``q h = 0``).

    Returns:
        ``(phi00, phi01, phi10, phi11, g1_0, g1_1, gs_0, gs_1)``.
    """
    m = -0.5 * a1 / epsilon
    det = a2 / (epsilon * epsilon)  # det A
    disc = m * m - det  # q^2: > 0 overdamped, < 0 underdamped, 0 critically damped
    x = math.sqrt(abs(disc)) * h
    if x <= 1e-6:
        c = 1.0 + 0.5 * disc * h * h
        s = h * (1.0 + disc * h * h / 6.0)
    elif disc > 0.0:
        c = math.cosh(x)
        s = h * math.sinh(x) / x
    else:
        c = math.cos(x)
        s = h * math.sin(x) / x
    e = math.exp(m * h)
    # A - m I = [[m, 1], [-det, -m]] (tr A = 2 m)
    p00, p01, p10, p11 = e * (c + s * m), e * s, -e * s * det, e * (c - s * m)
    # A^-1 = [[0, -1/det], [1, 2 m/det]]; I1 = A^-1 (Phi - I) = int_0^h exp(A s) ds
    i00, i01 = -p10 / det, -(p11 - 1.0) / det
    i10, i11 = (p00 - 1.0) + 2.0 * m * p10 / det, p01 + 2.0 * m * (p11 - 1.0) / det
    b0, b1 = -2.0 * m, det  # b = (a1/eps, a2/eps^2)
    # W = A^-1 (h Phi - I1) = int_0^h s exp(A s) ds
    n00, n01, n10, n11 = h * p00 - i00, h * p01 - i01, h * p10 - i10, h * p11 - i11
    w00, w01 = -n10 / det, -n11 / det
    w10, w11 = n00 + 2.0 * m * n10 / det, n01 + 2.0 * m * n11 / det
    return (p00, p01, p10, p11, i00 * b0 + i01 * b1, i10 * b0 + i11 * b1, w00 * b0 + w01 * b1,
            w10 * b0 + w11 * b1)


def transition_matrices(epsilon: float, a1: float, a2: float, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`transition` as arrays ``(Phi (2, 2), g1 (2,), gs (2,))``."""
    p00, p01, p10, p11, g0, g1, s0, s1 = transition(float(epsilon), float(a1), float(a2), float(step))
    return np.array([[p00, p01], [p10, p11]]), np.array([g0, g1]), np.array([s0, s1])


@njit
def observer_output(i, z, estimate):
    """Write row ``i``'s estimate ``X, Y, psi, vx, vy, omega`` from ``z[i]`` (rates rotated into the body frame)."""
    psi = z[i, 0, 2]
    c, s = math.cos(psi), math.sin(psi)
    x_rate, y_rate = z[i, 1, 0], z[i, 1, 1]
    estimate[i, 0] = z[i, 0, 0]
    estimate[i, 1] = z[i, 0, 1]
    estimate[i, 2] = psi
    estimate[i, 3] = c * x_rate + s * y_rate
    estimate[i, 4] = -s * x_rate + c * y_rate
    estimate[i, 5] = z[i, 1, 2]


@njit
def observer_reset(i, z, last, estimate, t, x, y, psi):
    """Start row ``i`` at the measured pose ``(x, y, psi)`` taken at ``t`` [s], at rest."""
    z[i, 0, 0], z[i, 0, 1], z[i, 0, 2] = x, y, psi
    z[i, 1, 0] = z[i, 1, 1] = z[i, 1, 2] = 0.0
    last[i, 0], last[i, 1], last[i, 2], last[i, 3] = t, x, y, psi
    observer_output(i, z, estimate)


@njit
def observer_update(i, z, last, estimate, t, x, y, psi, epsilon, a1, a2, max_gap):
    """Correct row ``i`` with the pose ``(x, y, psi)`` measured at ``t`` [s] (after ``last[i, 0]``).

    The first measurement (``last[i, 0]`` NaN), or one more than ``max_gap`` after the previous, starts the
    observer there (:func:`observer_reset`). Returns 1 for a restart after a gap, else 0.
    """
    t_last = last[i, 0]
    if math.isnan(t_last) or t - t_last > max_gap:
        observer_reset(i, z, last, estimate, t, x, y, psi)
        return 0 if math.isnan(t_last) else 1
    step = t - t_last
    predicted = z[i, 0, 2] + z[i, 1, 2] * step
    psi = predicted + (psi - predicted + math.pi) % (2.0 * math.pi) - math.pi  # unwrapped against the prediction
    p00, p01, p10, p11, g0, g1, s0, s1 = transition(epsilon, a1, a2, step)
    for k in range(3):
        u = x if k == 0 else (y if k == 1 else psi)
        slope = (u - last[i, 1 + k]) / step
        x1, x2 = z[i, 0, k], z[i, 1, k]
        z[i, 0, k] = p00 * x1 + p01 * x2 + g0 * u - s0 * slope
        z[i, 1, k] = p10 * x1 + p11 * x2 + g1 * u - s1 * slope
    last[i, 0], last[i, 1], last[i, 2], last[i, 3] = t, x, y, psi
    observer_output(i, z, estimate)
    return 0


@njit
def observer_predict(i, z, last, estimate, t):
    """Write row ``i``'s estimate at ``t`` >= its last measurement, rates held; ``z`` and ``last`` are unchanged."""
    elapsed = t - last[i, 0]
    psi = z[i, 0, 2] + z[i, 1, 2] * elapsed
    c, s = math.cos(psi), math.sin(psi)
    x_rate, y_rate = z[i, 1, 0], z[i, 1, 1]
    estimate[i, 0] = z[i, 0, 0] + x_rate * elapsed
    estimate[i, 1] = z[i, 0, 1] + y_rate * elapsed
    estimate[i, 2] = psi
    estimate[i, 3] = c * x_rate + s * y_rate
    estimate[i, 4] = -s * x_rate + c * y_rate
    estimate[i, 5] = z[i, 1, 2]


def frequency_response(omega: float, epsilon: float, a1: float = 2.0, a2: float = 1.0) -> complex:
    """Transfer function from a coordinate's true rate to its estimated rate at ``omega`` [rad/s].

    ``G(j omega) = wn^2 / (wn^2 - omega^2 + j 2 zeta wn omega)`` with ``wn^2 = a2 / eps^2`` and
    ``2 zeta wn = a1 / eps`` (the continuous observer; the first-order hold makes it exact for ramps).
    """
    wn2 = a2 / epsilon**2
    return wn2 / (wn2 - omega**2 + 1j * (a1 / epsilon) * omega)
