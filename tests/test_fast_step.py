"""The averaged model's fast step: its function approximations against libm and closed forms, and the option."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pectoral_gym.model import fast_step as fs
from pectoral_gym.model.dynamics import oscillating_square_mean
from pectoral_gym.model.params import FinBeat
from pectoral_gym.model.spec import AVERAGED, AveragedSpec, spec_from_dict


def _dense(low: float, high: float, count: int = 20001) -> np.ndarray:
    """A uniform grid plus Chebyshev points (which crowd the ends) of ``[low, high]``."""
    k = np.arange(count)
    cheb = low + (high - low) * 0.5 * (1.0 - np.cos(math.pi * (k + 0.5) / count))
    return np.concatenate([np.linspace(low, high, count), cheb])


def test_atan_within_its_bound_on_the_unit_interval():
    t = _dense(0.0, 1.0)[1:]
    got = np.array([fs.fast_atan_unit(float(x)) for x in t])
    assert np.max(np.abs(got / np.arctan(t) - 1.0)) < fs.ATAN_RELATIVE_ERROR
    assert fs.fast_atan_unit(0.0) == 0.0


@pytest.mark.parametrize("t, angle", [(1.0, math.pi / 4), (1.0 / math.sqrt(3.0), math.pi / 6),
                                      (2.0 - math.sqrt(3.0), math.pi / 12), (math.sqrt(2.0) - 1.0, math.pi / 8)])
def test_atan_at_closed_form_angles(t, angle):
    assert fs.fast_atan_unit(t) == pytest.approx(angle, rel=fs.ATAN_RELATIVE_ERROR)


def test_drift_angle_is_the_papers_arctan_in_every_quadrant():
    """eq. (20)'s ``alpha = arctan(vy / vx)`` in [-pi/2, pi/2], also for vx < 0 (swimming backward)."""
    angles = _dense(-math.pi, math.pi, 4001)
    for radius in (1e-6, 0.05, 3.0):
        for a in angles:
            vx, vy = radius * math.cos(a), radius * math.sin(a)
            expected = math.atan(vy / vx) if vx != 0.0 else math.copysign(math.pi / 2, vy)
            got = fs.drift_angle(vy, vx)
            assert abs(got - expected) <= fs.ATAN_RELATIVE_ERROR * abs(expected) + 1e-300, (vx, vy)
    assert fs.drift_angle(0.0, 0.0) == 0.0
    assert fs.drift_angle(0.3, 0.0) == pytest.approx(math.pi / 2, rel=1e-15)
    assert fs.drift_angle(-0.3, 0.0) == pytest.approx(-math.pi / 2, rel=1e-15)
    assert fs.drift_angle(0.2, -0.2) == pytest.approx(-math.pi / 4, rel=fs.ATAN_RELATIVE_ERROR)


def test_asin_within_its_bound_on_minus_one_to_one():
    x = _dense(-1.0, 1.0)
    x = x[x != 0.0]
    got = np.array([fs.fast_asin(float(v)) for v in x])
    assert np.max(np.abs(got / np.arcsin(x) - 1.0)) < fs.ASIN_RELATIVE_ERROR
    # both sides of the switch to the half-angle form
    for v in (0.5, np.nextafter(0.5, 1.0), np.nextafter(0.5, 0.0)):
        assert fs.fast_asin(v) == pytest.approx(math.asin(v), rel=fs.ASIN_RELATIVE_ERROR)


@pytest.mark.parametrize("x, angle", [(0.5, math.pi / 6), (math.sqrt(0.5), math.pi / 4),
                                      (math.sqrt(3.0) / 2, math.pi / 3), (1.0, math.pi / 2), (-1.0, -math.pi / 2),
                                      (0.0, 0.0)])
def test_asin_at_closed_form_angles(x, angle):
    assert fs.fast_asin(x) == pytest.approx(angle, rel=fs.ASIN_RELATIVE_ERROR, abs=1e-300)


def test_fast_oscillating_square_mean_is_the_cycle_mean():
    """Against a direct quadrature of ``x|x|`` over a cycle (independent of either closed form)."""
    theta = (np.arange(200000) + 0.5) * 2.0 * math.pi / 200000
    for amplitude in (0.0, 0.4, 2.0):
        for mean in (-3.0, -0.7, -0.1, 0.0, 0.05, 0.39, 0.41, 1.5):
            x = mean + amplitude * np.sin(theta)
            expected = float(np.mean(x * np.abs(x)))
            got = fs.fast_oscillating_square_mean(mean, amplitude)
            assert got == pytest.approx(expected, rel=1e-9, abs=1e-12)
            assert got == pytest.approx(oscillating_square_mean(mean, amplitude), rel=1e-11, abs=1e-15)


def test_spec_option_is_off_by_default_and_left_out_of_its_dict():
    assert AveragedSpec().fast_step is False
    assert "fast_step" not in AVERAGED.to_dict()
    on = AVERAGED.replace(fast_step=True)
    assert on.to_dict()["fast_step"] is True
    assert spec_from_dict(on.to_dict()) == on
    assert on.build(2).fast_step is True
    with pytest.raises(ValueError, match="fast_step"):
        AVERAGED.replace(fast_step="yes")


def _swim(spec, seconds=12.0):
    model = spec.build(3)
    model.reset()
    beats = [(FinBeat.from_degrees(90, 20, 1.0, 3), FinBeat.from_degrees(90, 20, 1.0, 3)),
             (FinBeat.from_degrees(70, 25, 0.8, 2), FinBeat.from_degrees(110, 10, 1.5, 4)),
             (FinBeat.from_degrees(120, 30, 0.6, 5), None)]
    for k in range(int(seconds / 2)):
        right, left = beats[k % 3]
        model.command(right=right, left=left)
        model.advance(2.0)
    return model.state.copy()


def test_fast_step_is_reproducible_and_close_to_the_default_step():
    default = _swim(AVERAGED)
    fast = _swim(AVERAGED.replace(fast_step=True))
    assert np.array_equal(fast, _swim(AVERAGED.replace(fast_step=True)))
    assert not np.array_equal(fast, default)  # the option reaches the kernel
    # a few mm after 12 s of turns and pattern changes (the fish swim metres)
    assert np.max(np.hypot(*(fast[:, :2] - default[:, :2]).T)) < 5e-3
    assert np.max(np.abs(fast[:, 2] - default[:, 2])) < math.radians(0.5)


def test_short_bessel_j1_against_scipy_within_its_range():
    from scipy.special import j1

    x = _dense(-math.pi / 2, math.pi / 2)
    got = np.array([fs.short_bessel_j1(float(v)) for v in x])
    assert np.max(np.abs(got - j1(x))) < fs.BESSEL_J1_ERROR
    # the series' own bound at the end of the range: the first term left out, |x/2|^19 / (9! 10!)
    assert (math.pi / 4) ** 19 / (math.factorial(9) * math.factorial(10)) < fs.BESSEL_J1_ERROR


def test_short_odd_moment_against_quadrature():
    from pectoral_gym.model.averaging import short_odd_moment

    nodes, weights = np.polynomial.legendre.leggauss(200)
    phi, weights = (nodes + 1.0) * math.pi / 2.0, weights * math.pi / 2.0
    for h in np.linspace(-math.pi / 2, math.pi / 2, 41):
        expected = float(np.sum(weights * (phi - math.pi / 2) * np.sin(phi) ** 2 * np.sin(h * np.cos(phi))))
        assert short_odd_moment(float(h)) == pytest.approx(expected, rel=1e-12, abs=2e-13)


def test_sin_cos_within_their_bound():
    x = _dense(-math.pi / 2, math.pi / 2)
    got = np.array([fs.sin_cos_half_turn(float(v)) for v in x])
    assert np.max(np.abs(got[:, 0] - np.sin(x))) < fs.SIN_COS_ERROR
    assert np.max(np.abs(got[:, 1] - np.cos(x))) < fs.SIN_COS_ERROR
    angles = _dense(0.0, math.pi)
    got = np.array([fs.sin_cos_of_angle(float(v)) for v in angles])
    assert np.max(np.abs(got[:, 0] - np.sin(angles))) < fs.SIN_COS_ERROR
    assert np.max(np.abs(got[:, 1] - np.cos(angles))) < fs.SIN_COS_ERROR
    # beyond the ranges: libm's own
    assert fs.sin_cos_half_turn(2.0) == (math.sin(2.0), math.cos(2.0))
    # the Taylor remainders at pi/2 that the bound covers
    assert (math.pi / 2) ** 17 / math.factorial(17) < fs.SIN_COS_ERROR
    assert (math.pi / 2) ** 18 / math.factorial(18) < fs.SIN_COS_ERROR


def test_fast_oscillation_gain_close_to_the_default_quadrature():
    """8 nodes and the polynomial sin/cos against the 12-node quadrature (itself within 3e-6 of exact)."""
    from pectoral_gym.model.params import FishParams
    from pectoral_gym.model.ripple import transitional_oscillation_gain

    params = FishParams()
    k, inertia = params.fin_drag_constant, params.fin_inertia_constant
    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(3000):
        bias, amp = rng.uniform(math.radians(45), math.radians(135)), rng.uniform(0.01, math.radians(30))
        period, ratio, power = rng.uniform(0.5, 2.0), rng.uniform(1.0, 5.0), bool(rng.integers(2))
        angle_from = rng.uniform(math.radians(15), math.radians(165))
        duration = period / (ratio + 1.0) * (1.0 if power else ratio)
        args = (angle_from, bias + amp if power else bias - amp, duration, power, bias, amp, period, ratio, k, inertia)
        worst = max(worst, abs(transitional_oscillation_gain(*args, True) / transitional_oscillation_gain(*args) - 1))
    assert 0.0 < worst < 5e-4


def test_fast_swept_cube_equals_the_closed_form():
    from pectoral_gym.model import strokes as st

    fins = np.zeros((1, 2, st.FIN_FIELDS))
    fins[0, 0, st.ANGLE_FROM], fins[0, 0, st.ANGLE_TO], fins[0, 0, st.DURATION] = 0.6, 2.1, 0.4
    for elapsed, seg in ((0.0, 0.4), (0.1, 0.2), (0.35, 0.3)):
        fins[0, 0, st.ELAPSED] = elapsed
        assert st.swept_cube(fins, 0, 0, seg, True) == pytest.approx(st.swept_cube(fins, 0, 0, seg), abs=1e-10)
    fins[0, 0, st.ELAPSED] = 0.0  # a whole half-stroke: |half|^3 (pi/d)^2 4/3
    assert st.swept_cube(fins, 0, 0, 0.4, True) == pytest.approx(0.75**3 * (math.pi / 0.4) ** 2 * 4 / 3, rel=1e-10)


def test_env_config_carries_the_option_to_the_averaged_spec_only():
    from pectoral_gym.envs.config import EnvConfig

    assert EnvConfig(model="averaged").model_spec().fast_step is False
    assert EnvConfig(model="averaged", fast_step=True).model_spec() == AVERAGED.replace(
        transitions=False, ripple_offsets=False, fast_step=True)
    assert EnvConfig(model="full", fast_step=True).model_spec() == EnvConfig(model="full").model_spec()
    with pytest.raises(ValueError, match="fast_step must be True or False"):
        EnvConfig(model="averaged", fast_step="yes")
