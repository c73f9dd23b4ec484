"""The fast step's exponential substep: its weights against quadrature, and the yaw rate against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pectoral_gym.model import fast_step as fs
from pectoral_gym.model.dynamics import Forcing, rate_constants
from pectoral_gym.model.params import BodyCoefficients, FishParams


def _phi(k: int, z: float) -> float:
    """``phi_k(z) = int_0^1 e^((1 - s) z) s^(k-1) / (k-1)! ds`` by 40-node Gauss-Legendre (exact to rounding here)."""
    x, w = np.polynomial.legendre.leggauss(40)
    s = 0.5 * (x + 1.0)
    return float(0.5 * np.sum(w * np.exp((1.0 - s) * z) * s ** (k - 1)) / math.factorial(k - 1))


@pytest.mark.parametrize("z", [0.0, -1e-7, -0.05, -0.1999, -0.2, -0.2001, -0.7, -2.0, -7.5, -40.0])
def test_weights_are_the_phi_functions_of_cox_and_matthews(z):
    """``f1 = phi1 - 3 phi2 + 4 phi3``, ``f2 = phi2 - 2 phi3``, ``f3 = 4 phi3 - phi2``; ratio ``phi1(z/2) / 2``."""
    half, ratio, f1, f2, f3 = fs.exponential_weights(z)
    p1, p2, p3 = _phi(1, z), _phi(2, z), _phi(3, z)
    assert half == pytest.approx(math.exp(0.5 * z), rel=1e-15)
    assert ratio == pytest.approx(0.5 * _phi(1, 0.5 * z), rel=1e-14)
    for got, expected in ((f1, p1 - 3.0 * p2 + 4.0 * p3), (f2, p2 - 2.0 * p3), (f3, 4.0 * p3 - p2)):
        assert got == pytest.approx(expected, rel=1e-12, abs=1e-15)


def _body():
    p = FishParams()
    return BodyCoefficients(p.m1, p.m2, p.J3, p.c1, p.c2, p.c4)


def _spin(omega0: float, tau: float, seconds: float, accurate: float, dt_max: float = 0.25):
    """The yaw rate of a fish at rest in translation (``vx = vy = 0`` stays) under a constant moment, and the steps."""
    b = _body()
    rates = rate_constants(b.m1, b.m2, b.J3, b.c1, b.c2, b.c4)
    state = np.array([[0.0, 0.0, 0.0, 0.0, 0.0, omega0]])
    integral = np.zeros((1, 3))
    c, s, t_left, steps = 1.0, 0.0, seconds, 0
    driven = math.sqrt(abs(tau) / (b.c4 * b.J3))
    while t_left > 1e-12:
        c, s, h = fs.exponential_substep(state, integral, 0, t_left, Forcing(0.0, 0.0, tau), b, rates, 0.0, driven,
                                         0.0, c, s, dt_max, accurate)
        t_left -= h
        steps += 1
    return state[0], integral[0], steps, b


@pytest.mark.parametrize("omega0", [0.0, 0.3, 2.0])
def test_yaw_rate_follows_the_closed_form_spin_up(omega0):
    """``J3 w' = tau - c4 J3 w|w|``: ``w = W tanh(c4 W t + atanh(w0 / W))`` (``W = sqrt(tau / (c4 J3))``, ``w0 < W``),
    ``W coth(...)`` from above; its integral ``log cosh`` (or ``sinh``) gives the heading."""
    b, seconds = _body(), 0.2
    tau = b.c4 * b.J3  # W = 1 rad/s
    state, integral, _, b = _spin(omega0, tau, seconds, fs.FAST_ACCURATE_STEP)
    big_w = math.sqrt(tau / (b.c4 * b.J3))
    rate = b.c4 * big_w
    if omega0 < big_w:
        start = math.atanh(omega0 / big_w)
        omega = big_w * math.tanh(rate * seconds + start)
        heading = (math.log(math.cosh(rate * seconds + start)) - math.log(math.cosh(start))) / b.c4
    else:
        start = math.atanh(big_w / omega0)
        omega = big_w / math.tanh(rate * seconds + start)
        heading = (math.log(math.sinh(rate * seconds + start)) - math.log(math.sinh(start))) / b.c4
    assert big_w == pytest.approx(1.0)  # the cases span both branches
    # the step's own error at its bound h * rate <= 2 (the first substep from rest is RK4's at h * 2 c4 W = 2):
    # measured 7.6e-4 in the rate and 1.3e-3 rad in the heading (the default step's: 3.7e-4, 9e-5 rad)
    assert state[5] == pytest.approx(omega, rel=1e-3)
    assert state[2] == pytest.approx(heading, abs=2e-3)
    assert integral[2] == state[2]  # the running integral of omega is the heading's own sum
    assert state[3] == 0.0 and state[4] == 0.0 and state[0] == 0.0 and state[1] == 0.0


def test_stiff_steps_stay_stable_where_rk4_would_not():
    """Steps far past RK4's limit (``2 c4 w h`` ~ 19 > 2.78) still settle on the equilibrium ``W`` exactly."""
    b = _body()
    tau = b.c4 * b.J3  # W = 1 rad/s
    state, _, steps, b = _spin(2.0, tau, 3.0, accurate=100.0, dt_max=0.25)
    assert steps == 12  # dt_max binds alone
    assert state[5] == pytest.approx(math.sqrt(tau / (b.c4 * b.J3)), rel=1e-9)


def test_an_equilibrium_does_not_move():
    """At ``w = W`` (zero acceleration) the exponential substep leaves the yaw rate where it is, to rounding."""
    b = _body()
    tau = 0.3 * b.c4 * b.J3
    big_w = math.sqrt(tau / (b.c4 * b.J3))
    state, _, _, _ = _spin(big_w, tau, 2.0, fs.FAST_ACCURATE_STEP)
    assert state[5] == pytest.approx(big_w, rel=1e-14)
