import math

import casadi as ca
import numpy as np
import pytest

from pectoral_gym.model.averaging import EXACT, averaged_fin_forcing, mean_fin_power
from pectoral_gym.model.dynamics import body_accel
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.models import AveragedModel
from pectoral_gym.model.params import FinBeat, FishParams, body_coefficients, coefficient_vector
from pectoral_gym.model.symbolic import (
    averaged_forcing_sx,
    averaged_rhs_sx,
    bessel_j1_sx,
    body_accel_sx,
    body_rhs_sx,
    mean_fin_power_sx,
    named_symbols,
    rk4_sx,
)

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
    ref = body_accel(*v, *forcing, *body_coefficients(PARAMS))
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
    model = AveragedModel(1, PARAMS, scaling=scaling, dt_max=1e-3, ripple_offsets=False)  # equations, not steps
    start = np.array([1.0, 0.5, 0.3, 0.02, -0.005, 0.1])
    model.reset(state=start[None], right=right.as_array()[None], left=left.as_array()[None])
    model.advance(2.0)
    x = ca.SX.sym("x", 6)
    beats = np.concatenate([right.as_array(), left.as_array()])
    f = ca.Function("f", [x], [averaged_rhs_sx(x, beats, PARAMS, scaling)])
    state = rk4_symbolic(f, start, 1e-3, 2000)  # RK4, 2 s
    np.testing.assert_allclose(state, model.state[0], rtol=1e-6, atol=1e-9)


def test_body_rhs_is_tank_frame_kinematics_plus_body_accelerations():
    # heading 90 deg: surge moves the fish along +Y, sway (to the left, +vy) along -X (eq. 19)
    state = [0.3, 0.2, math.pi / 2, 0.05, 0.01, -0.2]
    forcing = [0.01, -0.004, 2e-4]
    got = np.array(ca.DM(body_rhs_sx(state, forcing, PARAMS))).ravel()
    np.testing.assert_allclose(got[:3], [-0.01, 0.05, -0.2], atol=1e-15)
    np.testing.assert_array_equal(got[3:], np.array(ca.DM(body_accel_sx(state[3:], forcing, PARAMS))).ravel())


@pytest.mark.parametrize("steps", [1, 7])
def test_rk4_is_the_fourth_order_taylor_polynomial_on_a_linear_ode(steps):
    # dx/dt = lambda x: one classical RK4 step multiplies x by 1 + z + z^2/2 + z^3/6 + z^4/24, z = lambda h
    lam, h = -1.7, 0.13
    z = lam * h
    x = ca.SX.sym("x")
    end = ca.Function("end", [x], [rk4_sx(lambda y, rate: rate * y, x, lam, h, steps)])
    assert float(end(2.0)) == pytest.approx(2.0 * (1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24) ** steps, rel=1e-14)
    # a constant rate is integrated exactly, and the input is passed through unchanged
    assert float(ca.DM(rk4_sx(lambda y, u: u[0] - u[1], 1.0, (0.5, 0.2), h, steps))) == pytest.approx(
        1.0 + 0.3 * h * steps, rel=1e-15)
    with pytest.raises(ValueError, match="steps"):
        rk4_sx(lambda y, u: y, x, None, h, 0)


@pytest.mark.parametrize("deg", [(90, 20, 1.0, 3), (60, 27, 0.7, 1.4), (120, 5, 2.0, 4.8)])
def test_mean_fin_power_equals_numba_and_the_cycle_mean_of_eq_14(deg):
    beat = FinBeat.from_degrees(*deg)
    ref = mean_fin_power(beat.amplitude, beat.period, beat.ratio, PARAMS.fin_span, PARAMS.fin_drag_constant)
    assert float(mean_fin_power_sx(beat.amplitude, beat.period, beat.ratio, PARAMS)) == pytest.approx(ref, rel=1e-14)
    a = ca.SX.sym("a")
    power = ca.Function("p", [a], [mean_fin_power_sx(a, beat.period, beat.ratio, PARAMS)])
    assert float(power(beat.amplitude)) == pytest.approx(ref, rel=1e-14)
    # independently: the fin moment of eq. (14) gives the power (3 k S_p / 4)|g'|^3; average it over the
    # two strokes of eq. (21), g' = gA w sin(w t) for t in [0, pi / w], w = w1 (power) and w1 / zeta (recovery)
    w1 = math.pi * (beat.ratio + 1) / beat.period
    work = 0.0
    for w in (w1, w1 / beat.ratio):
        t = np.linspace(0.0, math.pi / w, 20001)
        rate = beat.amplitude * w * np.sin(w * t)
        work += np.trapezoid(0.75 * PARAMS.fin_drag_constant * PARAMS.fin_span * np.abs(rate) ** 3, t)
    assert ref == pytest.approx(work / beat.period, rel=1e-7)


def test_named_symbols_pack_in_field_order():
    from typing import NamedTuple

    class Layout(NamedTuple):
        first: int
        second: int

    parts = named_symbols(Layout(first=2, second=3))
    assert isinstance(parts, Layout) and parts.first.shape == (2, 1) and parts.second.shape == (3, 1)
    packed = ca.vertcat(*parts)
    picks = ca.Function("f", [packed], [parts.second[0], parts.first[1]])
    assert [float(v) for v in picks([10, 11, 12, 13, 14])] == [12.0, 11.0]


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


# --- transitional half-strokes (docs/model.md 3.7) ---------------------------------------------------------------

def _quadrature_mean_force(angle_from, angle_to, duration, n=20001):
    """Mean blade-element force (eqs. 9-17) over one half-cosine half-stroke, by the trapezoid rule."""
    from pectoral_gym.model.dynamics import fin_force_right, stroke_kinematics

    s = np.linspace(0.0, duration, n)
    f = np.array([fin_force_right(*stroke_kinematics(t, duration, angle_from, angle_to), PARAMS.fin_drag_constant,
                                  PARAMS.fin_inertia_constant) for t in s])
    return np.trapezoid(f, s, axis=0) / duration


@pytest.mark.parametrize("power", [True, False])
def test_transition_forcing_matches_quadrature_of_the_blade_element_forces(power):
    from pectoral_gym.model.symbolic_corrections import transition_forcing_sx

    beat = (1.3, 0.35, 0.9, 3.0)
    previous = (1.7, 0.2, 0.9, 3.0)
    angle_from = 1.05  # not the regular start
    d1 = beat[2] / (beat[3] + 1)
    bias, amp = beat[0], beat[1]
    if power:
        d, regular, to = d1, bias - amp, bias + amp
    else:
        d, regular, to = beat[3] * d1, bias + amp, bias - amp
    expected = _quadrature_mean_force(angle_from, to, d) - _quadrature_mean_force(regular, to, d)
    if not power:  # the power-stroke excess X = d1 (mean power stroke - cycle mean), by quadrature
        def excess(b):
            e1, e2 = b[2] / (b[3] + 1), b[3] * b[2] / (b[3] + 1)
            p = _quadrature_mean_force(b[0] - b[1], b[0] + b[1], e1)
            r = _quadrature_mean_force(b[0] + b[1], b[0] - b[1], e2)
            return e1 * p - e1 * (e1 * p + e2 * r) / b[2]
        expected = expected + (excess(previous) - excess(beat)) / d
    for side in (1.0, -1.0):
        got = np.array(ca.DM(transition_forcing_sx(angle_from, beat, previous, power, side, PARAMS))).ravel()
        want = [expected[0], side * expected[1], side * PARAMS.fin_offset * expected[0]]
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-12)


def test_expected_transition_impulse_is_the_phase_average_of_the_compiled_model():
    """Drag-free body, mirrored fins (no sway, no yaw): the surge velocity the transitional forcing adds
    (transitions on minus off, K = 1) is its impulse / m1. Averaged over switch times spread uniformly over
    one beat of the old pattern, it is the expectation the NMPC plans with."""
    from pectoral_gym.model.symbolic_corrections import expected_transition_impulse_sx

    params = FishParams().replace(drag_coef=1e-6, lift_coef=1e-6, moment_coef=1e-6)  # ~drag-free; steps stay ~ms
    a = FinBeat.from_degrees(80, 20, 0.8, 4.0)
    b = FinBeat.from_degrees(100, 28, 0.8, 4.0)
    m1 = body_coefficients(params)[0]
    n_phases = 200
    models = {on: AveragedModel(1, params, scaling="none", transitions=on) for on in (False, True)}
    gains = []
    for k in range(n_phases):
        speed = {}
        for on, model in models.items():
            model.reset(right=a, left=a)
            model.advance((k + 0.5) / n_phases * a.period)
            model.command(right=b, left=b)
            model.advance(3 * a.period)  # the transitional strokes are over
            speed[on] = model.state[0, 3]
        gains.append(speed[True] - speed[False])
    measured = np.mean(gains) * m1
    impulse = ca.DM(expected_transition_impulse_sx(a.as_array(), b.as_array(), 1.0, params)).full().ravel()
    assert abs(impulse[0]) > 1e-4  # the switch matters at all
    np.testing.assert_allclose(measured, 2 * impulse[0], rtol=1e-3)  # two fins; the phase grid is midpoint-exact
    same = ca.DM(expected_transition_impulse_sx(b.as_array(), b.as_array(), -1.0, params)).full().ravel()
    np.testing.assert_allclose(same, 0.0, atol=1e-15)
