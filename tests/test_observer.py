"""High-gain observer against closed-form motions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pectoral_gym.hardware.vision.observer import HighGainObserver


def _circle(t, radius=0.3, rate=0.5, centre=(1.1, 0.6)):
    """Swimming counter-clockwise on a circle, heading along the tangent: vx = R w, vy = 0, omega = w."""
    phase = rate * t
    return centre[0] + radius * math.cos(phase), centre[1] + radius * math.sin(phase), phase + math.pi / 2


def _wrap(angle):
    return (angle + math.pi) % (2 * math.pi) - math.pi


@pytest.mark.parametrize("irregular", [False, True], ids=["30Hz", "irregular"])
def test_circular_motion_matches_the_closed_form_frequency_response(irregular):
    radius, rate, epsilon = 0.3, 0.5, 0.1
    observer = HighGainObserver(epsilon=epsilon)
    rng = np.random.default_rng(0)
    t = 0.0
    observer.reset(*_circle(t), t)
    while t < 20.0:  # transients die as exp(-t / eps)
        t += rng.uniform(0.01, 0.08) if irregular else 1 / 30
        x, y, psi = _circle(t)
        estimate = observer.update(t, x, y, _wrap(psi))
    # For the observer the true velocity is a complex exponential; it scales and turns it by G(j w), so in
    # the body frame (vx + j vy) = G(j w) R w, omega = w (psi is a ramp, followed exactly).
    gain = observer.frequency_response(rate)
    wn2, damping = 1 / epsilon**2, 2 / epsilon
    assert gain == pytest.approx(wn2 / (wn2 - rate**2 + 1j * damping * rate))  # a1 = 2, a2 = 1
    speed = radius * rate
    assert abs(gain.imag) * speed > 0.005  # the lag is visible: a test of it can fail
    np.testing.assert_allclose(estimate[:2], _circle(t)[:2], atol=2e-3)
    assert estimate[2] == pytest.approx(_circle(t)[2], abs=1e-6)  # unwrapped, not wrapped
    assert estimate[3] == pytest.approx(gain.real * speed, abs=0.01 * speed)
    assert estimate[4] == pytest.approx(gain.imag * speed, abs=0.01 * speed)
    assert estimate[5] == pytest.approx(rate, rel=1e-6)


def test_ramp_is_followed_exactly_at_any_spacing():
    # straight line at constant speed and constant turning rate: both are ramps
    observer = HighGainObserver(epsilon=0.05)
    times = np.cumsum(np.random.default_rng(1).uniform(0.005, 0.3, 200))
    velocity, omega = np.array([0.05, -0.02]), 0.2
    observer.reset(0.5, 0.5, 0.0, 0.0)
    for t in times:
        estimate = observer.update(t, 0.5 + velocity[0] * t, 0.5 + velocity[1] * t, _wrap(omega * t))
    psi = omega * times[-1]
    body = np.array([[math.cos(psi), math.sin(psi)], [-math.sin(psi), math.cos(psi)]]) @ velocity
    np.testing.assert_allclose(estimate[3:5], body, atol=1e-8)
    assert estimate[5] == pytest.approx(omega, abs=1e-8)


def test_heading_unwraps_across_pi():
    observer = HighGainObserver(epsilon=0.1)
    rate = -0.8  # clockwise through +-pi several times
    observer.reset(0.0, 0.0, math.pi - 0.1, 0.0)
    psi_true = math.pi - 0.1
    for k in range(1, 400):
        t = k / 25
        psi_true = math.pi - 0.1 + rate * t
        estimate = observer.update(t, 0.0, 0.0, _wrap(psi_true))
        assert abs(estimate[5] - rate) < 0.9 * abs(rate) or k < 10  # never a 2 pi / dt spike
    assert estimate[2] == pytest.approx(psi_true, abs=1e-6)
    assert estimate[5] == pytest.approx(rate, abs=1e-6)


def test_predict_extrapolates_and_does_not_change_the_state():
    observer = HighGainObserver(epsilon=0.05)
    observer.reset(0.0, 0.0, 0.0, 0.0)
    for k in range(1, 200):
        observer.update(k * 0.02, 0.1 * k * 0.02, 0.0, 0.0)
    before = observer.estimate
    predicted = observer.predict(4.0 + 0.5)
    assert predicted[0] == pytest.approx(before[0] + 0.1 * 0.52, abs=1e-6)
    np.testing.assert_allclose(predicted[3:], before[3:])
    after = observer.update(4.0, 0.4, 0.0, 0.0)  # the state was not advanced by predict
    assert after[0] == pytest.approx(0.4, abs=1e-6)
    assert observer.time == 4.0


def test_restart_after_a_long_gap_and_input_errors():
    observer = HighGainObserver(epsilon=0.1, max_gap=0.5)
    with pytest.raises(RuntimeError, match="no pose"):
        observer.predict(0.0)
    assert np.all(np.isnan(observer.estimate))
    first = observer.update(1.0, 0.2, 0.3, 0.4)  # first measurement starts the observer at rest
    np.testing.assert_allclose(first, [0.2, 0.3, 0.4, 0, 0, 0])
    restarted = observer.update(2.0, 1.2, 0.3, 0.4)  # 1 s gap > max_gap: no 1 m/s made-up velocity
    np.testing.assert_allclose(restarted, [1.2, 0.3, 0.4, 0, 0, 0])
    assert observer.restarts == 1
    with pytest.raises(ValueError, match="not after"):
        observer.update(2.0, 1.2, 0.3, 0.4)
    with pytest.raises(ValueError, match="finite"):
        observer.update(2.1, math.nan, 0.3, 0.4)
    with pytest.raises(ValueError, match="epsilon"):
        HighGainObserver(epsilon=0.0)


def test_noise_is_filtered_less_as_epsilon_shrinks():
    rng = np.random.default_rng(2)
    spreads = []
    for epsilon in (0.2, 0.05):
        observer = HighGainObserver(epsilon=epsilon)
        observer.reset(1.0, 0.5, 0.0, 0.0)
        estimates = [observer.update(k / 30, 1.0 + rng.normal(0, 1e-3), 0.5, 0.0)[3] for k in range(1, 600)]
        spreads.append(np.std(estimates[100:]))
    assert spreads[1] > 2 * spreads[0]
