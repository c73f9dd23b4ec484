import math

import casadi as ca
import numpy as np
import pytest

from pectoral_gym.averaging import EXACT, averaged_fin_forcing
from pectoral_gym.dynamics import body_accel
from pectoral_gym.kfunctions import ScalingFunctions
from pectoral_gym.models import AveragedModel
from pectoral_gym.params import FinBeat, FishParams, coefficient_vector
from pectoral_gym.symbolic import averaged_forcing_sx, averaged_rhs_sx, bessel_j1_sx, body_accel_sx

PARAMS = FishParams()


def _scaling():
    # K_fx = 0.9, K_fy = 1.2 + 0.5 amplitude, K_m = 0.4 + 0.1 / period: one term per feature kind
    powers = np.zeros((3, 2, 6))
    coefs = np.zeros((3, 2))
    coefs[0, 0] = 0.9
    coefs[1] = [1.2, 0.5]
    powers[1, 1, 1] = 1
    coefs[2] = [0.4, 0.1]
    powers[2, 1, 4] = 1
    return ScalingFunctions(powers, coefs, {})


def test_bessel_series_matches_scipy_free_reference():
    # J1(x) = (1/pi) int_0^pi cos(tau - x sin tau) dtau, by the trapezoid rule (spectrally accurate here)
    tau = np.linspace(0, math.pi, 2001)
    for x in (0.05, 0.3, 0.52, 1.5):
        ref = np.trapezoid(np.cos(tau - x * np.sin(tau)), tau) / math.pi
        assert float(bessel_j1_sx(x)) == pytest.approx(ref, rel=1e-9)


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_forcing_equals_numba_averaged_forcing(side):
    scaling = _scaling()
    beat = FinBeat.from_degrees(70, 20, 0.8, 3)
    ref = averaged_fin_forcing(beat.bias, beat.amplitude, beat.period, beat.ratio, side,
                               coefficient_vector(PARAMS), EXACT, scaling.kernel_arrays())
    got = np.array(ca.DM(averaged_forcing_sx(beat.as_array(), side, PARAMS, scaling))).ravel()
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-15)
    assert ref[1] * side > 0  # cos(70 deg) > 0: the mirror flips the sway force


@pytest.mark.parametrize("v", [(0.05, 0.01, 0.3), (-0.02, 0.015, -0.2), (0.03, -0.02, 0.0)])
def test_body_accel_equals_numba(v):
    forcing = (0.01, -0.004, 2e-4)
    c = coefficient_vector(PARAMS)
    ref = body_accel(*v, *forcing, *c[:6])
    got = np.array(ca.DM(body_accel_sx(list(v), list(forcing), PARAMS))).ravel()
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-15)
    smooth = np.array(ca.DM(body_accel_sx(list(v), list(forcing), PARAMS, smoothing=1e-7))).ravel()
    np.testing.assert_allclose(smooth, ref, rtol=1e-6, atol=1e-12)


def test_smoothed_model_has_finite_gradient_at_rest():
    v = ca.SX.sym("v", 3)
    jac = ca.Function("j", [v], [ca.jacobian(body_accel_sx(v, [0.0, 0.0, 0.0], PARAMS, smoothing=1e-4), v)])
    assert np.all(np.isfinite(np.array(jac([0.0, 0.0, 0.0]))))


def test_rk4_of_symbolic_rhs_tracks_averaged_model(rk4_symbolic):
    scaling = _scaling()
    right, left = FinBeat.from_degrees(80, 20, 1.0, 4), FinBeat.from_degrees(100, 10, 0.6, 2)
    model = AveragedModel(1, PARAMS, scaling=scaling, dt_max=1e-3)  # compare equations, not step sizes
    start = np.array([1.0, 0.5, 0.3, 0.02, -0.005, 0.1])
    model.reset(state=start[None], right=right.as_array()[None], left=left.as_array()[None])
    model.advance(2.0)
    x = ca.SX.sym("x", 6)
    beats = np.concatenate([right.as_array(), left.as_array()])
    f = ca.Function("f", [x], [averaged_rhs_sx(x, beats, PARAMS, scaling)])
    state = rk4_symbolic(f, start, 1e-3, 2000)  # RK4, 2 s
    np.testing.assert_allclose(state, model.state[0], rtol=1e-6, atol=1e-9)


def _spline_scaling():
    from scipy.interpolate import make_interp_spline

    rng = np.random.default_rng(5)
    nodes = (np.radians([45, 60, 75, 95, 110, 135]), np.radians([2.5, 10, 17, 24, 30]), 1 / np.array([5, 3, 2, 1.25]))
    knots = tuple(make_interp_spline(n, np.zeros_like(n), k=3).t for n in nodes)
    return ScalingFunctions(np.zeros((3, 1, 6)), np.zeros((3, 1)), {}, knots, rng.normal(0.5, 0.3, (3, 6, 5, 4)),
                            "base")


@pytest.mark.parametrize("deg", [(90, 20, 1.0, 3), (52, 27, 0.7, 1.4), (130, 3, 2.0, 4.8)])
@pytest.mark.parametrize("side", [1.0, -1.0])
def test_spline_forcing_equals_numba_and_is_differentiable(deg, side):
    scaling = _spline_scaling()
    beat = FinBeat.from_degrees(*deg)
    ref = averaged_fin_forcing(beat.bias, beat.amplitude, beat.period, beat.ratio, side,
                               coefficient_vector(PARAMS), EXACT, scaling.kernel_arrays())
    x = ca.SX.sym("x", 4)
    f = ca.Function("f", [x], [averaged_forcing_sx([x[i] for i in range(4)], side, PARAMS, scaling)])
    np.testing.assert_allclose(np.array(f(beat.as_array())).ravel(), ref, rtol=1e-12, atol=1e-15)
    # The solver's Jacobian (C2 spline: exact derivatives) against central differences of the compiled model.
    jac = np.array(ca.Function("j", [x], [ca.jacobian(f(x), x)])(beat.as_array()))
    h = 1e-6
    for k in range(4):
        up, down = beat.as_array().copy(), beat.as_array().copy()
        up[k] += h
        down[k] -= h
        fd = (np.array(averaged_fin_forcing(*up, side, coefficient_vector(PARAMS), EXACT, scaling.kernel_arrays()))
              - np.array(averaged_fin_forcing(*down, side, coefficient_vector(PARAMS), EXACT,
                                              scaling.kernel_arrays()))) / (2 * h)
        np.testing.assert_allclose(jac[:, k], fd, rtol=1e-5, atol=1e-9 * np.abs(ref).max())
