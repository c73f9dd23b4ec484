"""Oscillation-averaged yaw damping of the averaged model (beyond the paper; docs/model.md section 3.6).

Checked against independent computations: numerical quadrature of the cycle
mean, scipy root solves on a separately written damping, the time-scale
symmetry of the full model, and mirror symmetry.
"""

import dataclasses
import json
import math

import numpy as np
import pytest
from scipy import optimize
from scipy.interpolate import NdBSpline, make_interp_spline

from pectoral_gym.model import forcing_cache as fc
from pectoral_gym.model.dynamics import body_accel as averaged_body_accel
from pectoral_gym.model.dynamics import oscillating_square_mean
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.models import AveragedModel
from pectoral_gym.model.params import FinBeat, FishParams, body_coefficients
from pectoral_gym.model.steady import steady_state_batch
from pectoral_gym.scaling.identification.reference import reference_runs, yaw_oscillation_statistics

P = FishParams()
THETA = 2 * np.pi * (np.arange(200_000) + 0.5) / 200_000  # midpoint rule: spectrally accurate for smooth periodic


def _quadrature_mean(mean, amplitude):
    x = mean + amplitude * np.sin(THETA)
    return float(np.mean(x * np.abs(x)))


@pytest.mark.parametrize("mean", [-0.7, -0.3, -0.05, 0.0, 0.01, 0.2, 0.299, 0.3, 0.301, 0.9])
def test_oscillating_square_mean_equals_quadrature(mean):
    assert oscillating_square_mean(mean, 0.3) == pytest.approx(_quadrature_mean(mean, 0.3), rel=1e-6, abs=1e-12)


def test_oscillating_square_mean_limits_slope_and_symmetry():
    assert oscillating_square_mean(0.4, 0.0) == 0.4 * 0.4  # no oscillation: the paper's w|w|
    assert oscillating_square_mean(-0.4, 0.0) == -0.4 * 0.4
    for w in (0.05, 0.2, 0.5):
        assert oscillating_square_mean(-w, 0.25) == -oscillating_square_mean(w, 0.25)  # odd in the mean
    # slope 4 A / pi at zero mean (linear damping), by central differences
    h = 1e-6
    slope = (oscillating_square_mean(h, 0.25) - oscillating_square_mean(-h, 0.25)) / (2 * h)
    assert slope == pytest.approx(4 * 0.25 / math.pi, rel=1e-6)
    # continuous derivative where the oscillation stops crossing zero (|w| = A)
    left = (oscillating_square_mean(0.25 - 1e-7, 0.25) - oscillating_square_mean(0.25 - 2e-7, 0.25)) / 1e-7
    right = (oscillating_square_mean(0.25 + 2e-7, 0.25) - oscillating_square_mean(0.25 + 1e-7, 0.25)) / 1e-7
    assert left == pytest.approx(2 * 0.25, rel=1e-5) and right == pytest.approx(2 * 0.25, rel=1e-5)


def test_symbolic_mean_matches_and_has_finite_derivatives():
    ca = pytest.importorskip("casadi")
    from pectoral_gym.model.symbolic import oscillating_square_mean_sx

    w = ca.SX.sym("w")
    f = ca.Function("f", [w], [oscillating_square_mean_sx(w, 0.3), ca.jacobian(oscillating_square_mean_sx(w, 0.3), w)])
    for mean in (-0.5, -0.3, -0.1, 0.0, 0.1, 0.3, 0.5):
        value, slope = (float(v) for v in f(mean))
        assert value == pytest.approx(oscillating_square_mean(mean, 0.3), rel=1e-12, abs=1e-15)
        h = 1e-6
        fd = (oscillating_square_mean(mean + h, 0.3) - oscillating_square_mean(mean - h, 0.3)) / (2 * h)
        assert math.isfinite(slope) and slope == pytest.approx(fd, rel=1e-5)


def test_statistics_recover_a_sinusoid_amplitude_and_phase():
    samples = 64
    theta = 2 * np.pi * np.arange(1, samples + 1) / samples
    omega = 0.07 + 0.2 * np.cos(theta + 2.5)
    amplitude, phase = yaw_oscillation_statistics(omega[None])
    # (pi/2) mean|A cos| = A; the 64-point rule of |cos| is exact to ~1e-3 (a kink at each zero)
    assert amplitude[0] == pytest.approx(0.2, rel=2e-3)
    assert phase[0] == pytest.approx(2.5, abs=1e-12)


def test_full_model_yaw_oscillation_is_period_free():
    # Time-scale symmetry of eqs. (9)-(20): omega ~ 1/T_p, so A T_p and the phase do not depend on T_p.
    pattern = np.array([math.radians(70), math.radians(25), 1.0, 3.0])
    ref = reference_runs(np.array([pattern, pattern * [1, 1, 2.5, 1]]), P, progress=False)
    assert ref.yaw_oscillation[0] > 3 * abs(ref.velocities[0, 2])  # oscillates by more than its mean
    assert ref.yaw_oscillation[1] * 2.5 == pytest.approx(ref.yaw_oscillation[0], rel=1e-5)
    assert ref.yaw_phase[1] == pytest.approx(ref.yaw_phase[0], abs=1e-5)


def _oscillation_scaling(level=0.3, phase=-2.0, k=1.0):
    """K = k and a constant yaw-oscillation phasor A T_p = level at angle ``phase`` (a spline of constants)."""
    nodes = (np.radians([45, 70, 95, 135]), np.radians([5, 15, 25, 30]), 1 / np.array([5, 3, 2, 1.25]))
    knots = tuple(make_interp_spline(n, np.zeros_like(n), k=3).t for n in nodes)
    table = np.empty((2, 4, 4, 4))
    table[0], table[1] = level * math.cos(phase), level * math.sin(phase)
    unit = ScalingFunctions.unit()
    return dataclasses.replace(unit, coefs=np.full((3, 1), k), oscillation_knots=knots, oscillation_table=table)


def test_phasor_is_the_spline_and_shrinks_linearly_below_the_lowest_amplitude():
    s = _oscillation_scaling()
    amplitude, phase = s.yaw_oscillation(math.radians(80), math.radians(20), 2.0, 3.0)
    assert amplitude == pytest.approx(0.3 / 2.0, rel=1e-12) and phase == pytest.approx(-2.0, rel=1e-12)
    low = s.yaw_oscillation(math.radians(80), math.radians(2.5), 1.0, 3.0)[0]
    assert low == pytest.approx(0.3 * 2.5 / 5.0, rel=1e-12)
    assert s.yaw_oscillation(math.radians(80), 0.0, 1.0, 3.0) == (0.0, 0.0)  # a fin at rest
    # a non-constant table against scipy's independent tensor-product spline
    rng = np.random.default_rng(3)
    table = rng.normal(0.0, 0.3, size=(2, 4, 4, 4))
    s = dataclasses.replace(s, oscillation_table=table)
    x = (math.radians(77), math.radians(21), 1 / 2.6)
    pc, ps = (float(NdBSpline(s.oscillation_knots, table[i], 3)(x)) for i in range(2))
    amplitude, phase = s.yaw_oscillation(x[0], x[1], 1.5, 2.6)
    assert amplitude == pytest.approx(math.hypot(pc, ps) / 1.5, rel=1e-12)
    assert phase == pytest.approx(math.atan2(ps, pc), rel=1e-12)


def test_averaged_steady_turn_balances_the_oscillation_averaged_damping():
    # Steady state of the averaged model (K = 1, one fin) against a root solve of eq. (19) whose yaw
    # damping is the quadrature mean over the oscillation, written here independently of the package.
    s = _oscillation_scaling(level=0.35)
    beat = FinBeat.from_degrees(85, 25, 1.0, 1.5)
    beats = np.array([[beat.as_array(), FinBeat.rest().as_array()]])
    model = AveragedModel(1, P, scaling=s)
    steady = steady_state_batch(model, beats, rtol=1e-9, atol=1e-12)[0]
    forcing = np.array(model.forcing_cache[0, 0, fc.AVG_FX:fc.AVG_TAU + 1])
    m1, m2, j3, c1, c2, c4 = body_coefficients(P)
    amplitude = 0.35 / beat.period

    def rhs(v):
        vx, vy, w = v
        speed = math.hypot(vx, vy)
        alpha = math.atan2(vy, vx)
        return [
            (m2 * vy * w - c1 * vx * speed + c2 * vy * speed * alpha + forcing[0]) / m1,
            (-m1 * vx * w - c1 * vy * speed - c2 * vx * speed * alpha + forcing[1]) / m2,
            (m1 - m2) / j3 * vx * vy - c4 * _quadrature_mean(w, amplitude) + forcing[2] / j3,
        ]

    root = optimize.fsolve(rhs, [steady.vx, steady.vy, steady.omega], xtol=1e-10)
    np.testing.assert_allclose([steady.vx, steady.vy, steady.omega], root, rtol=1e-5)
    paper = steady_state_batch(AveragedModel(1, P, scaling=dataclasses.replace(
        s, oscillation_knots=(), oscillation_table=None)), beats, rtol=1e-9, atol=1e-12)[0]
    assert abs(paper.omega) > 1.2 * abs(steady.omega)  # the extra damping matters at this slow turn


def test_mirrored_fins_in_phase_cancel_and_mirror_images_mirror():
    s = _oscillation_scaling(level=0.35)
    right = FinBeat.from_degrees(80, 25, 1.0, 3.0)
    left = FinBeat.from_degrees(80, 25, 1.0, 3.0)
    with_osc, without = AveragedModel(1, P, scaling=s), AveragedModel(1, P, scaling=ScalingFunctions.unit())
    for m in (with_osc, without):
        m.reset(right=right, left=left, state=[0, 0, 0, 0.02, 0.0, 0.05])  # a yaw perturbation
        m.advance(7.3)
    # equal patterns beating in phase: the oscillations cancel, so the damping is the paper's exactly
    np.testing.assert_array_equal(with_osc.state, without.state)
    a, b = AveragedModel(1, P, scaling=s), AveragedModel(1, P, scaling=s)
    a.reset(right=FinBeat.from_degrees(70, 25, 1.0, 3.0), left=FinBeat.from_degrees(95, 15, 1.3, 2.0))
    b.reset(right=FinBeat.from_degrees(95, 15, 1.3, 2.0), left=FinBeat.from_degrees(70, 25, 1.0, 3.0))
    a.advance(23.0)
    b.advance(23.0)
    np.testing.assert_allclose(b.state[0], a.state[0] * [1, -1, -1, 1, -1, -1], rtol=1e-12, atol=1e-15)


def test_averaged_body_accel_differs_only_in_yaw_damping():
    coef = body_coefficients(P)
    v, f = (0.05, -0.01, 0.04), (0.01, -0.002, 1e-4)
    paper = np.array(averaged_body_accel(*v, *f, *coef, 0.0))
    osc = np.array(averaged_body_accel(*v, *f, *coef, 0.2))
    np.testing.assert_array_equal(osc[:2], paper[:2])
    c4 = coef.c4
    assert osc[2] - paper[2] == pytest.approx(c4 * (0.04 * 0.04 - _quadrature_mean(0.04, 0.2)), rel=1e-6)


OSC_MALFORMED = [
    (lambda d: d["yaw_oscillation"].update(degree=2), "degree 3"),
    (lambda d: d["yaw_oscillation"].pop("sin"), "malformed yaw_oscillation"),
    (lambda d: d["yaw_oscillation"].update(cos=[1.0, 2.0]), "malformed yaw_oscillation"),
    (lambda d: d["yaw_oscillation"].update(extrapolation="linear"), "extrapolation"),
    (lambda d: d["yaw_oscillation"]["knots"][1].reverse(), "non-decreasing"),
    (lambda d: d.update(yaw_oscillation=3), "must be an object"),
]


@pytest.mark.parametrize("mutate,message", OSC_MALFORMED)
def test_oscillation_section_round_trips_and_malformed_sections_raise(tmp_path, mutate, message):
    s = _oscillation_scaling()
    path = tmp_path / "k.json"
    s.save(path)
    back = ScalingFunctions.load(path)
    assert back.has_oscillation and not back.is_unit
    np.testing.assert_array_equal(back.oscillation_table, s.oscillation_table)
    assert back.yaw_oscillation(1.3, 0.3, 1.0, 2.0) == s.yaw_oscillation(1.3, 0.3, 1.0, 2.0)
    data = json.loads(path.read_text())
    mutate(data)
    with pytest.raises(ValueError, match=message):
        ScalingFunctions.from_dict(data, "k.json")


def test_nmpc_with_oscillation_equals_the_algebraic_solution():
    pytest.importorskip("casadi")
    from pectoral_gym.scaling.identification.nmpc import (
        IdentificationNmpcSettings,
        ScalingNmpc,
        algebraic_scaling,
        unscaled_forcing,
    )

    patterns = np.array([FinBeat.from_degrees(85, 25, 1.0, 1.5).as_array(),
                         FinBeat.from_degrees(60, 20, 1.0, 4).as_array()])
    ref = reference_runs(patterns, P, progress=False)
    forcing = unscaled_forcing(patterns, P, sway="base")
    oracle = algebraic_scaling(ref.velocities, forcing, P, ref.yaw_oscillation)
    paper = algebraic_scaling(ref.velocities, forcing, P)
    nmpc = ScalingNmpc(P, IdentificationNmpcSettings(horizon=3.0), ref.velocities, ref.yaw_oscillation)
    for i in range(len(patterns)):
        r = nmpc.solve(ref.velocities[i], forcing[i], oscillation=ref.yaw_oscillation[i])
        assert r.success
        np.testing.assert_allclose(r.k, oracle[i], rtol=1e-3)
    # only the yaw moment's scaling changes, and it moves towards 1 (the missing damping was in K_m)
    np.testing.assert_array_equal(oracle[:, :2], paper[:, :2])
    assert np.all(np.abs(oracle[:, 2] - 1) < np.abs(paper[:, 2] - 1))


CACHE_BEAT = FinBeat.from_degrees(80, 25, 1.0, 3.0)


def _beating_model():
    """An averaged model (K = 1) whose right fin has beaten ``CACHE_BEAT`` for 2.3 s."""
    model = AveragedModel(1, P, scaling="none")
    model.reset(right=CACHE_BEAT)
    model.advance(2.3)
    return model


def test_latch_reuses_the_forcing_of_an_unchanged_pattern_but_not_after_new_parameters():
    from pectoral_gym.model.averaging import averaged_forcing

    beat, model = CACHE_BEAT, _beating_model()
    assert model.forcing_cache[0, 0, fc.CACHED] == 1.0
    np.testing.assert_allclose(model.forcing_cache[0, 0, fc.AVG_FX:fc.AVG_TAU + 1], averaged_forcing(beat, P),
                               rtol=1e-14)
    heavier = dataclasses.replace(P, fin_force_coef=2 * P.fin_force_coef)
    model.set_params(heavier)  # the averaged forcing depends on the parameters: the cache is invalid
    assert model.forcing_cache[0, 0, fc.CACHED] == 0.0
    model.advance(1.0)  # at least one latch (a whole fin period)
    np.testing.assert_allclose(model.forcing_cache[0, 0, fc.AVG_FX:fc.AVG_TAU + 1], averaged_forcing(beat, heavier),
                               rtol=1e-14)


def test_reset_to_rest_drops_the_cached_forcing_of_the_last_beat():
    # A fin reset to rest never latches again: the forcing of its earlier pattern must not stay in force.
    model = _beating_model()
    assert np.any(model.state[0, 3:] != 0.0)
    model.reset()
    model.advance(5.0)
    np.testing.assert_array_equal(model.state[0], np.zeros(6))  # at rest, no force: stays at rest exactly


def test_new_scaling_tables_invalidate_the_cache():
    model = _beating_model()
    assert model.forcing_cache[0, 0, fc.CACHED] == 1.0
    model.tables = _oscillation_scaling(level=0.35).kernel_arrays()
    assert model.forcing_cache[0, 0, fc.CACHED] == 0.0


@pytest.mark.parametrize("left", [None, (100, 10, 1.0, 2.0)])
def test_symbolic_rhs_with_oscillation_tracks_the_averaged_model(left, rk4_symbolic):
    # One fin, or two fins with equal periods (their beat phases stay equal, as the symbolic model assumes).
    ca = pytest.importorskip("casadi")
    from pectoral_gym.model.symbolic import averaged_rhs_sx

    table = np.random.default_rng(7).normal(0, 0.3, (2, 4, 4, 4))  # phasors differ between the two patterns
    s = dataclasses.replace(_oscillation_scaling(), oscillation_table=table)
    right = FinBeat.from_degrees(80, 20, 1.0, 4.0)
    left = FinBeat.rest() if left is None else FinBeat.from_degrees(*left)
    model = AveragedModel(1, P, scaling=s, dt_max=1e-3, ripple_offsets=False)  # compare equations, not steps
    start = np.array([1.0, 0.5, 0.3, 0.02, -0.005, 0.1])
    model.reset(state=start[None], right=right.as_array()[None], left=left.as_array()[None])
    model.advance(2.0)
    x = ca.SX.sym("x", 6)
    f = ca.Function("f", [x], [averaged_rhs_sx(x, np.concatenate([right.as_array(), left.as_array()]), P, s)])
    state = rk4_symbolic(f, start, 1e-3, 2000)
    np.testing.assert_allclose(state, model.state[0], rtol=1e-6, atol=1e-9)
