"""Yaw-waveform damping of the averaged model (beyond the paper; docs/model.md section 3.6).

Checked against independent computations: fine quadrature of the cycle mean written here,
the closed form of the sinusoid damping, scipy's tensor-product splines, a root solve of
eq. (19) with a separately written damping, mirror symmetry, and the symbolic model.
"""

import dataclasses
import json
import math

import numpy as np
import pytest
from scipy import optimize
from scipy.interpolate import NdBSpline, make_interp_spline

from pectoral_gym.model import forcing_cache as fc
from pectoral_gym.model.averaging import averaged_body_accel, equivalent_amplitude, waveform_samples
from pectoral_gym.model.dynamics import oscillating_square_mean, waveform_square_mean
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.ktables import MAX_HARMONICS, QUADRATURE
from pectoral_gym.model.models import AveragedModel
from pectoral_gym.model.params import FinBeat, FishParams, body_coefficients
from pectoral_gym.model.steady import steady_state_batch
from pectoral_gym.scaling.identification.reference import yaw_oscillation_statistics, yaw_waveform_harmonics
from pectoral_gym.scaling.identification.regression import fit_waveform

P = FishParams()
NODES = (np.radians([45, 70, 95, 135]), np.radians([5, 15, 25, 30]), 1 / np.array([5, 3, 2, 1.25]))
KNOTS = tuple(make_interp_spline(n, np.zeros_like(n), k=3).t for n in NODES)


def _fine_mean(mean, harmonics, phase=0.0, points=100_000):
    """Mean of x|x| over x = mean + Re sum_k c_k e^{ik theta}, midpoint rule on a fine grid."""
    theta = phase + 2 * np.pi * (np.arange(points) + 0.5) / points
    k = np.arange(1, len(harmonics) + 1)
    x = mean + np.real(np.asarray(harmonics) @ np.exp(1j * np.outer(k, theta)))
    return float(np.mean(x * np.abs(x)))


def _waveform_scaling(harmonics, k=1.0, rng=None):
    """K = k and constant yaw-waveform harmonics ``T_p c_k = harmonics`` (a spline of constants; random if rng)."""
    h = len(harmonics)
    table = np.empty((2 * h, 4, 4, 4))
    for i, c in enumerate(harmonics):
        table[2 * i], table[2 * i + 1] = c.real, c.imag
    if rng is not None:
        table = table + rng.normal(0.0, 0.05, table.shape)
    unit = ScalingFunctions.unit()
    return dataclasses.replace(unit, coefs=np.full((3, 1), k), waveform_knots=KNOTS, waveform_table=table)


WAVE = np.array([0.25 * np.exp(-2.0j), 0.08 * np.exp(0.7j), 0.03 * np.exp(2.1j)])  # T_p c_k [rad]


def test_quadrature_of_one_harmonic_is_the_sinusoid_closed_form():
    # a single harmonic is a sinusoid: the closed form of the oscillation damping, to the 32-point rule's accuracy
    for mean in (-0.3, -0.05, 0.0, 0.02, 0.15, 0.4):
        samples = waveform_samples(np.array([0.2 * np.exp(0.4j)]))
        assert samples.shape == (QUADRATURE,)
        assert waveform_square_mean(mean, samples) == pytest.approx(oscillating_square_mean(mean, 0.2), abs=2e-4)
    # no sign change within the beat: x|x| = x^2 there, a trigonometric polynomial the rule integrates exactly
    samples = waveform_samples(WAVE / 2.0, phase=0.3)
    assert waveform_square_mean(0.5, samples) == pytest.approx(_fine_mean(0.5, WAVE / 2.0), rel=1e-12)
    assert waveform_square_mean(0.3, np.zeros(0)) == 0.3 * 0.3  # no waveform: the paper's w|w|


def test_quadrature_with_sign_changes_is_close_to_the_fine_mean_at_any_phase():
    for mean in (-0.08, 0.0, 0.03, 0.11):
        fine = _fine_mean(mean, WAVE)
        for phase in (0.0, 0.5, 2.0):
            assert waveform_square_mean(mean, waveform_samples(WAVE, phase)) == pytest.approx(fine, abs=3e-5)
    # odd in the mean (the mirror-image waveform), linear near zero with slope 2 mean|o|
    s = waveform_samples(WAVE)
    assert waveform_square_mean(-0.05, -s) == pytest.approx(-waveform_square_mean(0.05, s), rel=1e-14)
    slope = (waveform_square_mean(1e-7, s) - waveform_square_mean(-1e-7, s)) / 2e-7
    assert slope == pytest.approx(2 * np.mean(np.abs(s)), rel=1e-6)
    assert equivalent_amplitude(s) == pytest.approx(0.5 * np.pi * np.mean(np.abs(s)))


def test_harmonics_recover_a_known_waveform_and_agree_with_the_fundamental_phase():
    samples = 64
    theta = 2 * np.pi * np.arange(1, samples + 1) / samples
    omega = 0.07 + np.real(WAVE @ np.exp(1j * np.outer(np.arange(1, 4), theta)))
    c = yaw_waveform_harmonics(omega[None], 5)[0]
    np.testing.assert_allclose(c[:3], WAVE, atol=1e-14)
    np.testing.assert_allclose(c[3:], 0.0, atol=1e-14)
    assert np.angle(c[0]) == pytest.approx(yaw_oscillation_statistics(omega[None])[1][0], abs=1e-12)
    with pytest.raises(ValueError, match="harmonics must be in"):
        yaw_waveform_harmonics(omega[None], 32)


def test_waveform_is_the_spline_per_period_and_shrinks_below_the_lowest_amplitude():
    rng = np.random.default_rng(5)
    s = _waveform_scaling(WAVE, rng=rng)
    assert s.harmonics == 3 and not s.is_unit
    x = (math.radians(77), math.radians(21), 1 / 2.6)
    expected = [complex(NdBSpline(KNOTS, s.waveform_table[2 * i], 3)(x), NdBSpline(KNOTS, s.waveform_table[2 * i + 1],
                                                                                   3)(x)) for i in range(3)]
    np.testing.assert_allclose(s.yaw_waveform(x[0], x[1], 1.5, 2.6), np.array(expected) / 1.5, rtol=1e-12)
    low = s.yaw_waveform(x[0], math.radians(2.5), 1.0, 2.6)
    at_node = s.yaw_waveform(x[0], math.radians(5), 1.0, 2.6)
    np.testing.assert_allclose(low, at_node * 0.5, rtol=1e-12)
    assert np.all(s.yaw_waveform(x[0], 0.0, 1.0, 2.6) == 0)  # a fin at rest
    assert len(ScalingFunctions.unit().yaw_waveform(*x, 1.0)) == 0


WAVE_MALFORMED = [
    (lambda d: d["yaw_waveform"].update(harmonics=4), "'harmonics' is 4"),
    (lambda d: d["yaw_waveform"].pop("sin"), "malformed yaw_waveform"),
    (lambda d: d["yaw_waveform"]["cos"].__setitem__(0, [1.0, 2.0]), "malformed yaw_waveform"),
    (lambda d: d["yaw_waveform"].update(degree=2), "degree 3"),
]


@pytest.mark.parametrize("mutate,message", WAVE_MALFORMED)
def test_waveform_section_round_trips_and_malformed_sections_raise(tmp_path, mutate, message):
    s = _waveform_scaling(WAVE, rng=np.random.default_rng(1))
    path = tmp_path / "k.json"
    s.save(path)
    back = ScalingFunctions.load(path)
    np.testing.assert_array_equal(back.waveform_table, s.waveform_table)
    np.testing.assert_array_equal(back.yaw_waveform(1.3, 0.3, 1.0, 2.0), s.yaw_waveform(1.3, 0.3, 1.0, 2.0))
    data = json.loads(path.read_text())
    mutate(data)
    with pytest.raises(ValueError, match=message):
        ScalingFunctions.from_dict(data, "k.json")


def test_too_many_harmonics_are_refused():
    with pytest.raises(ValueError, match="harmonics"):
        _waveform_scaling(np.full(MAX_HARMONICS + 1, 0.01 + 0j))


def test_fit_waveform_interpolates_period_free_harmonics_on_the_grid():
    b, a, r = np.meshgrid(*NODES, indexing="ij")
    patterns = np.column_stack([b.ravel(), a.ravel(), np.full(b.size, 2.0), 1 / r.ravel()])
    t_c = np.column_stack([0.1 * patterns[:, 0] + 0.05j * patterns[:, 1], 0.02 * (1 + 1j) * patterns[:, 3]])
    knots, table = fit_waveform(patterns, t_c / 2.0, 2)
    s = dataclasses.replace(ScalingFunctions.unit(), waveform_knots=knots, waveform_table=table)
    for p, expected in zip(patterns[::7], t_c[::7], strict=True):
        np.testing.assert_allclose(s.yaw_waveform(*p[:2], 3.0, p[3]), expected / 3.0, rtol=1e-10, atol=1e-14)


def test_averaged_steady_turn_balances_the_waveform_damping():
    # One fin: the steady state of the compiled averaged model (K = 1) against a root solve of eq. (19)
    # whose yaw damping is the fine-quadrature mean over the waveform, written here.
    s = _waveform_scaling(WAVE)
    beat = FinBeat.from_degrees(85, 25, 1.0, 1.5)
    beats = np.array([[beat.as_array(), FinBeat.rest().as_array()]])
    model = AveragedModel(1, P, scaling=s)
    steady = steady_state_batch(model, beats, rtol=1e-9, atol=1e-12)[0]
    forcing = np.array(model.forcing_cache[0, 0, fc.AVG_FX:fc.AVG_TAU + 1])
    np.testing.assert_allclose(model.forcing_cache[0, 0, fc.WAVE:fc.WAVE + 6:2], WAVE.real / beat.period, rtol=1e-12)
    m1, m2, j3, c1, c2, c4 = body_coefficients(P)

    def rhs(v):
        vx, vy, w = v
        speed = math.hypot(vx, vy)
        alpha = math.atan2(vy, vx)
        return [
            (m2 * vy * w - c1 * vx * speed + c2 * vy * speed * alpha + forcing[0]) / m1,
            (-m1 * vx * w - c1 * vy * speed - c2 * vx * speed * alpha + forcing[1]) / m2,
            (m1 - m2) / j3 * vx * vy - c4 * _fine_mean(w, WAVE / beat.period) + forcing[2] / j3,
        ]

    root = optimize.fsolve(rhs, [steady.vx, steady.vy, steady.omega], xtol=1e-12)
    np.testing.assert_allclose([steady.vx, steady.vy, steady.omega], root, rtol=2e-3)  # 32-point rule
    assert abs(rhs([steady.vx, steady.vy, steady.omega])[2]) < 1e-3 * c4 * _fine_mean(steady.omega, WAVE)


def test_mirrored_fins_in_phase_cancel_and_mirror_images_mirror():
    s = _waveform_scaling(WAVE, rng=np.random.default_rng(2))
    with_wave, without = AveragedModel(1, P, scaling=s), AveragedModel(1, P, scaling=ScalingFunctions.unit())
    beat = FinBeat.from_degrees(80, 25, 1.0, 3.0)
    for m in (with_wave, without):
        m.reset(right=beat, left=beat, state=[0, 0, 0, 0.02, 0.0, 0.05])
        m.advance(7.3)
    np.testing.assert_allclose(with_wave.state, without.state, rtol=1e-13, atol=1e-16)  # waveforms cancel
    a, b = AveragedModel(1, P, scaling=s), AveragedModel(1, P, scaling=s)
    one, two = FinBeat.from_degrees(70, 25, 1.0, 3.0), FinBeat.from_degrees(95, 15, 1.3, 2.0)
    a.reset(right=one, left=two)
    b.reset(right=two, left=one)
    a.advance(23.0)
    b.advance(23.0)
    np.testing.assert_allclose(b.state[0], a.state[0] * [1, -1, -1, 1, -1, -1], rtol=1e-11, atol=1e-15)


def test_two_fins_in_phase_combine_their_waveforms_before_the_damping():
    # Equal periods, different strokes: the damping is that of the summed (mirrored) waveforms at their
    # phase, not the sum of the two fins' dampings. Steady state against a root solve written here.
    rng = np.random.default_rng(4)
    s = _waveform_scaling(WAVE, rng=rng)
    right, left = FinBeat.from_degrees(70, 25, 1.0, 3.0), FinBeat.from_degrees(95, 15, 1.0, 2.0)
    model = AveragedModel(1, P, scaling=s)
    steady = steady_state_batch(model, np.array([[right.as_array(), left.as_array()]]), rtol=1e-9, atol=1e-12)[0]
    forcing = model.forcing_cache[0, 0, fc.AVG_FX:fc.AVG_TAU + 1] + model.forcing_cache[0, 1, fc.AVG_FX:fc.AVG_TAU + 1]
    combined = s.yaw_waveform(*right.as_array()) - s.yaw_waveform(*left.as_array())
    body = body_coefficients(P)

    def rhs(v):
        out = list(averaged_body_accel(*v, *forcing, *body, 0.0))
        out[2] += body.c4 * (v[2] * abs(v[2]) - _fine_mean(v[2], combined))
        return out

    root = optimize.fsolve(rhs, [steady.vx, steady.vy, steady.omega], xtol=1e-12)
    np.testing.assert_allclose([steady.vx, steady.vy, steady.omega], root, rtol=5e-3)
    separate = -(s.yaw_waveform(*left.as_array()))
    assert abs(_fine_mean(steady.omega, combined) - _fine_mean(steady.omega, separate)
               - _fine_mean(steady.omega, s.yaw_waveform(*right.as_array()))) > 1e-3  # it matters here


@pytest.mark.parametrize("left", [None, (100, 10, 1.0, 2.0)])
def test_symbolic_rhs_with_waveform_tracks_the_averaged_model(left, rk4_symbolic):
    # One fin, or two with equal periods (in phase, as the symbolic model assumes). The yaw rate stays above
    # the waveform's reach, so x|x| = x^2 over the beat and the quadrature is exact at any beat phase.
    ca = pytest.importorskip("casadi")
    from pectoral_gym.model.symbolic import averaged_rhs_sx

    s = _waveform_scaling(WAVE * 0.1, rng=np.random.default_rng(7))
    s = dataclasses.replace(s, waveform_table=s.waveform_table * 0.1)
    right = FinBeat.from_degrees(80, 20, 1.0, 4.0)
    left = FinBeat.rest() if left is None else FinBeat.from_degrees(*left)
    model = AveragedModel(1, P, scaling=s, dt_max=1e-3, ripple_offsets=False)
    start = np.array([1.0, 0.5, 0.3, 0.02, -0.005, 0.3])
    model.reset(state=start[None], right=right.as_array()[None], left=left.as_array()[None])
    model.advance(2.0)
    assert model.state[0, 5] > 0.1
    x = ca.SX.sym("x", 6)
    f = ca.Function("f", [x], [averaged_rhs_sx(x, np.concatenate([right.as_array(), left.as_array()]), P, s)])
    state = rk4_symbolic(f, start, 1e-3, 2000)
    np.testing.assert_allclose(state, model.state[0], rtol=1e-6, atol=1e-9)


def test_nmpc_with_waveform_equals_the_algebraic_solution():
    pytest.importorskip("casadi")
    from pectoral_gym.scaling.identification.nmpc import (
        IdentificationNmpcSettings,
        ScalingNmpc,
        algebraic_scaling,
        unscaled_forcing,
    )

    patterns = np.array([FinBeat.from_degrees(85, 25, 1.0, 1.5).as_array(),
                         FinBeat.from_degrees(60, 20, 1.0, 4).as_array()])
    velocities = np.array([[0.05, -0.01, 0.1], [0.03, -0.02, 0.2]])
    samples = waveform_samples(np.array([WAVE, WAVE * 0.5]))
    forcing = unscaled_forcing(patterns, P, sway="base")
    oracle = algebraic_scaling(velocities, forcing, P, samples)
    body = body_coefficients(P)
    for v, f, k, o in zip(velocities, forcing, oracle, samples, strict=True):  # the oracle balances the yaw row
        w = v[2]
        yaw = (body.m1 - body.m2) / body.J3 * v[0] * v[1] - body.c4 * waveform_square_mean(w, o) + k[2] * f[2] / body.J3
        assert abs(yaw) < 1e-12
    nmpc = ScalingNmpc(P, IdentificationNmpcSettings(horizon=3.0), velocities, samples)
    for i in range(len(patterns)):
        r = nmpc.solve(velocities[i], forcing[i], oscillation=samples[i])
        assert r.success
        np.testing.assert_allclose(r.k, oracle[i], rtol=1e-3)


def _rate_scaling(harmonics, mean_abs, rng=None):
    """As :func:`_waveform_scaling`, with the reference runs' mean |omega| (T_p |omega|_ref = mean_abs) as well."""
    s = _waveform_scaling(harmonics, rng=rng)
    table = np.concatenate([s.waveform_table, np.full((1, 4, 4, 4), mean_abs)])
    return dataclasses.replace(s, waveform_table=table)


def _compiled_samples(model, omega):
    work = np.zeros(fc.WORKSPACE)
    c4 = body_coefficients(P).c4
    n, _ = fc.yaw_waveform(model.fins, model.forcing_cache, 0, 0.0, False, False, 3, True, omega, c4, work)
    return work[:n]


def _phase(model, f):
    return fc._beat_phase(model.fins, 0, f, 0.0)


def test_rate_correction_is_exact_at_the_reference_and_the_linear_response_elsewhere(tmp_path):
    s = _rate_scaling(WAVE, 0.3)
    assert s.has_rate_correction and s.harmonics == 3
    s.save(tmp_path / "k.json")
    back = ScalingFunctions.load(tmp_path / "k.json")
    assert back.has_rate_correction and back.yaw_mean_abs(1.2, 0.3, 2.0, 2.0) == pytest.approx(0.15, rel=1e-12)
    beat = FinBeat.from_degrees(80, 20, 1.0, 3.0)
    model = AveragedModel(1, P, scaling=s)
    model.reset(right=beat, left=FinBeat.rest())
    model.advance(0.37)
    c4 = body_coefficients(P).c4
    plain = waveform_samples(WAVE, _phase(model, 0))
    # the yaw rate at which the plain waveform's mean |omega| is the reference's: a fixed point, nothing changes
    w_ref = optimize.brentq(lambda w: np.mean(np.abs(w + plain)) - 0.3, 0.0, 1.0)
    np.testing.assert_allclose(_compiled_samples(model, w_ref), plain, atol=1e-12)
    # elsewhere, harmonic k is the drive c_k (lambda_ref + i k Omega) through 1 / (lambda + i k Omega), lambda the
    # damping rate 2 c4 mean|omega + o| of the result: the self-consistent solution, found here by bisection
    k = np.arange(1, 4)
    drive = WAVE * np.exp(1j * k * _phase(model, 0)) * (2 * c4 * 0.3 + 1j * k * 2 * np.pi)
    for w in (0.02, 0.6):
        def gap(lam, w=w):
            return 2 * c4 * np.mean(np.abs(w + waveform_samples(drive / (lam + 1j * k * 2 * np.pi)))) - lam
        lam = optimize.brentq(gap, 1e-6, 200.0)
        exact = waveform_samples(drive / (lam + 1j * k * 2 * np.pi))
        got = _compiled_samples(model, w)
        assert np.max(np.abs(got - exact)) < 0.05 * np.max(np.abs(exact))  # 3 relaxed fixed-point steps
        assert np.max(np.abs(got - plain)) > 0.1 * np.max(np.abs(plain))  # and the correction is not small


def _two_fin_waves(right, left, duration):
    """A rate-corrected scaling, a model advanced ``duration`` s with two fins, and each fin's waveform at its phase."""
    s = _rate_scaling(WAVE, 0.3, rng=np.random.default_rng(9))
    model = AveragedModel(1, P, scaling=s)
    model.reset(right=right, left=left)
    model.advance(duration)
    k = np.arange(1, 4)
    waves = np.array([s.yaw_waveform(*right.as_array()) * np.exp(1j * k * _phase(model, 0)),
                      -s.yaw_waveform(*left.as_array()) * np.exp(1j * k * _phase(model, 1))])
    return s, model, waves


def test_compiled_rate_corrected_waveform_equals_the_numpy_form_for_two_fins():
    from pectoral_gym.model.averaging import combined_waveform

    right, left = FinBeat.from_degrees(70, 25, 1.0, 3.0), FinBeat.from_degrees(95, 15, 1.4, 2.0)
    s, model, waves = _two_fin_waves(right, left, 2.9)
    mean_abs = np.array([s.yaw_mean_abs(*right.as_array()), s.yaw_mean_abs(*left.as_array())])
    expected = combined_waveform(waves, mean_abs, np.array([1.0, 1.4]), 0.07, body_coefficients(P).c4)
    np.testing.assert_allclose(_compiled_samples(model, 0.07), expected, rtol=1e-10, atol=1e-13)
    assert len(expected) == QUADRATURE  # 1.0 s and 1.4 s: no common period within 4 beats


def test_commensurate_periods_average_over_the_common_period():
    from pectoral_gym.model.averaging import combined_waveform
    from pectoral_gym.model.ktables import quadrature_window

    assert quadrature_window(2 * np.pi / 1.8, 2 * np.pi / 0.9) == (2 * QUADRATURE, 1, 2)
    assert quadrature_window(2 * np.pi / 0.6, 2 * np.pi / 0.9) == (3 * QUADRATURE, 3, 2)
    assert quadrature_window(2 * np.pi / 1.0, 2 * np.pi / 1.37)[0] == QUADRATURE
    right, left = FinBeat.from_degrees(70, 25, 1.8, 3.0), FinBeat.from_degrees(95, 15, 0.9, 2.0)
    s, model, waves = _two_fin_waves(right, left, 3.3)
    got = _compiled_samples(model, 0.07)
    np.testing.assert_allclose(got, combined_waveform(waves, np.array(
        [s.yaw_mean_abs(*right.as_array()), s.yaw_mean_abs(*left.as_array())]), np.array([1.8, 0.9]), 0.07,
        body_coefficients(P).c4), rtol=1e-10, atol=1e-13)
    # without the rate correction: the two waveforms in time, each at its own rate, written out here
    t = np.arange(2 * QUADRATURE) * 1.8 / (2 * QUADRATURE)
    direct = sum(np.real(np.exp(1j * np.outer(t * 2 * np.pi / period, np.arange(1, 4))) @ w)
                 for w, period in zip(waves, (1.8, 0.9), strict=True))
    np.testing.assert_allclose(combined_waveform(waves, None, np.array([1.8, 0.9]), 0.07, 1.0), direct, atol=1e-13)


def test_symbolic_rhs_with_rate_correction_tracks_the_averaged_model(rk4_symbolic):
    ca = pytest.importorskip("casadi")
    from pectoral_gym.model.symbolic import averaged_rhs_sx

    s = _rate_scaling(WAVE * 0.1, 0.05, rng=np.random.default_rng(7))
    s = dataclasses.replace(s, waveform_table=s.waveform_table * 0.1)
    right, left = FinBeat.from_degrees(80, 20, 1.0, 4.0), FinBeat.from_degrees(100, 10, 1.0, 2.0)
    model = AveragedModel(1, P, scaling=s, dt_max=1e-3, ripple_offsets=False)
    start = np.array([1.0, 0.5, 0.3, 0.02, -0.005, 0.3])
    model.reset(state=start[None], right=right.as_array()[None], left=left.as_array()[None])
    x = ca.SX.sym("x", 6)
    f = ca.Function("f", [x], [averaged_rhs_sx(x, np.concatenate([right.as_array(), left.as_array()]), P, s)])
    # the compiled model freezes the waveform over each segment (its yaw rate at the segment start), the
    # symbolic one follows the state: compare one half-stroke's worth of short steps
    model.advance(0.2)
    state = rk4_symbolic(f, start, 1e-3, 200)
    np.testing.assert_allclose(state, model.state[0], rtol=1e-4, atol=1e-7)


def test_full_model_yaw_harmonics_are_period_free():
    # Time-scale symmetry of eqs. (9)-(20): omega ~ 1/T_p, so T_p c_k does not depend on T_p.
    from pectoral_gym.scaling.identification.reference import reference_runs

    pattern = np.array([math.radians(70), math.radians(25), 1.0, 3.0])
    ref = reference_runs(np.array([pattern, pattern * [1, 1, 2.5, 1]]), P, progress=False)
    scale = abs(ref.yaw_harmonics[0, 0])
    np.testing.assert_allclose(ref.yaw_harmonics[1] * 2.5, ref.yaw_harmonics[0], atol=1e-5 * scale)
    assert abs(ref.yaw_harmonics[0, 1]) > 0.1 * abs(ref.yaw_harmonics[0, 0])  # a skewed waveform: not one sinusoid


def test_identify_refuses_an_unusable_harmonics_count():
    from pectoral_gym.scaling.identification.grids import GRIDS
    from pectoral_gym.scaling.identification.identify import identify

    with pytest.raises(ValueError, match="harmonics must be in"):
        identify(GRIDS["quick"], yaw_damping="waveform", harmonics=MAX_HARMONICS + 1, progress=False)
