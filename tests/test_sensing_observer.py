"""The batched high-gain observer (pectoral_gym.sensing.observer) against the robot's and against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pectoral_gym.hardware.vision.observer import HighGainObserver
from pectoral_gym.sensing import observer as hg


def _wrap(angle):
    return (angle + math.pi) % (2 * math.pi) - math.pi


def _arrays(n):
    return np.zeros((n, 2, 3)), np.full((n, 4), np.nan), np.full((n, 6), np.nan)


def test_batched_rows_equal_the_robot_observer_bit_for_bit():
    """Three streams with wraps of psi, irregular spacing, a gap past max_gap and predictions, interleaved."""
    rng = np.random.default_rng(7)
    n, epsilon, max_gap = 3, 0.08, 0.5
    z, last, estimate = _arrays(n)
    singles = [HighGainObserver(epsilon=epsilon, max_gap=max_gap) for _ in range(n)]
    t = np.zeros(n)
    restarts = np.zeros(n, dtype=int)
    for k in range(400):
        for i in range(n):
            t[i] += rng.uniform(0.01, 0.1) if k != 200 + i else 0.8  # one gap past max_gap per stream
            pose = (1.0 + 0.3 * math.sin(t[i]) + rng.normal(0, 2e-3), 0.5 + 0.1 * t[i],
                    _wrap(1.3 * t[i] + i + rng.normal(0, 0.02)))
            expected = singles[i].update(t[i], *pose)
            restarts[i] += hg.observer_update(i, z, last, estimate, t[i], *pose, epsilon, hg.A1, hg.A2, max_gap)
            assert np.array_equal(estimate[i], expected)
            if k % 7 == 0:
                later = t[i] + 0.05
                assert np.array_equal(singles[i].predict(later), _predict(z, last, i, later))
    assert restarts.tolist() == [s.restarts for s in singles] == [1, 1, 1]


def _predict(z, last, i, t):
    out = np.zeros((z.shape[0], 6))
    hg.observer_predict(i, z, last, out, t)
    return out[i]


@pytest.mark.parametrize("a1, a2", [(2.0, 1.0), (3.0, 1.0), (1.0, 2.0)], ids=["critical", "overdamped", "underdamped"])
@pytest.mark.parametrize("step", [1e-4, 1 / 30, 0.5])
def test_transition_is_the_exact_first_order_hold_discretisation(a1, a2, step):
    """Against the matrix exponential of the augmented system d/dt [x1, x2, u, u'] = ... with u'' = 0 (scipy)."""
    from scipy.linalg import expm

    epsilon = 0.07
    system = np.zeros((4, 4))
    system[0, :3] = (-a1 / epsilon, 1.0, a1 / epsilon)
    system[1, :3] = (-a2 / epsilon**2, 0.0, a2 / epsilon**2)
    system[2, 3] = 1.0
    z0, u0, u1 = np.array([0.3, -0.2]), 0.1, 0.25
    reference = (expm(system * step) @ np.array([*z0, u0, (u1 - u0) / step]))[:2]
    phi, g1, gs = hg.transition_matrices(epsilon, a1, a2, step)
    np.testing.assert_allclose(phi @ z0 + g1 * u1 - gs * (u1 - u0) / step, reference, rtol=1e-9, atol=1e-12)


def test_a_ramp_is_followed_without_error():
    """Constant velocity and turning rate: after the start transient (exp(-t/eps)), the estimate is exact."""
    n, epsilon = 2, 0.1
    z, last, estimate = _arrays(n)
    velocity, omega = np.array([[0.05, -0.02], [-0.1, 0.03]]), np.array([0.2, -0.7])
    times = np.cumsum(np.random.default_rng(1).uniform(0.005, 0.1, 800))
    for t in times:
        for i in range(n):
            hg.observer_update(i, z, last, estimate, t, 0.5 + velocity[i, 0] * t, 0.5 + velocity[i, 1] * t,
                               _wrap(omega[i] * t), epsilon, hg.A1, hg.A2, 1.0)
    for i in range(n):
        psi = omega[i] * times[-1]
        body = np.array([[math.cos(psi), math.sin(psi)], [-math.sin(psi), math.cos(psi)]]) @ velocity[i]
        np.testing.assert_allclose(estimate[i, :2], 0.5 + velocity[i] * times[-1], atol=1e-9)
        assert estimate[i, 2] == pytest.approx(psi, abs=1e-9)  # unwrapped
        np.testing.assert_allclose(estimate[i, 3:5], body, atol=1e-9)
        assert estimate[i, 5] == pytest.approx(omega[i], abs=1e-9)


def test_the_steady_response_to_a_sinusoid_has_the_filters_gain():
    """y = A sin(w t) at w = wn = 1/eps (critically damped): the rate estimate is G(jw) A w cos(w t), G = -j/2."""
    epsilon, amplitude, w, rate = 0.1, 0.02, 10.0, 600.0
    z, last, estimate = _arrays(1)
    assert hg.frequency_response(w, epsilon) == pytest.approx(-0.5j)  # wn^2 / (2 j zeta wn^2), zeta = 1
    gain = hg.frequency_response(w, epsilon)
    errors = []
    for k in range(1, 6001):  # 10 s; transients die as exp(-t / eps)
        t = k / rate
        hg.observer_update(0, z, last, estimate, t, amplitude * math.sin(w * t), 0.0, 0.0, epsilon, hg.A1, hg.A2, 1.0)
        if t > 5.0:
            expected = (gain * amplitude * w * np.exp(1j * w * t)).real  # rate of Re(A e^{j(wt - pi/2)}) through G
            errors.append(z[0, 1, 0] - expected)
    # the first-order hold of a sinusoid sampled at h errs by about (w h)^2 / 12 relative: 2e-5 here
    assert max(abs(e) for e in errors) < 1e-3 * amplitude * w * abs(gain)
