"""Cycle-averaged fin forcing (eqs. 25-28) and the Bessel closed form (K itself: ``tests/test_scaling_functions.py``).

References:

* numerical quadrature (scipy ``quad``) over one period of the full forcing,
  eq. (21) fed into the blade-element force (itself checked in ``test_forces``);
* ``scipy.special.j1`` for the Bessel function;
* the paper's eqs. (26)-(28) typed in here (with ``l_p = 1`` and the ``S_p^3``
  that the extraction lost in (27)-(28), without the ``m_p`` terms of (27));
* hand-derived fourth-order Taylor remainders of the closed form.
"""

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import j1

from pectoral_gym.model.averaging import EXACT, TAYLOR, averaged_fin_forcing, averaged_forcing, bessel_j1
from pectoral_gym.model.dynamics import fin_angle_eq21, fin_force_right
from pectoral_gym.model.kfunctions import FEATURES, FORMAT, ScalingFunctions
from pectoral_gym.model.params import FinBeat, FishParams, coefficient_vector

P = FishParams()
K_DRAG = P.fin_force_coef * P.water_density * P.fin_chord * P.fin_span**3 / 6.0
UNIT_K = ScalingFunctions.unit().kernel_arrays()

PATTERNS = [
    (90, 20, 1.0, 4.0),
    (100, 12, 0.8, 5.0),
    (60, 30, 0.5, 0.5),  # zeta < 1: net thrust reverses
    (130, 40, 2.0, 3.0),  # bias > 90 deg
    (45, 45, 1.5, 2.0),  # stroke touches 0 deg
    (170, 10, 0.66, 6.0),
    (95, 12, 1.0, 1.0),  # zeta = 1: symmetric beat, no net force
]


def quad_average(beat, drag_constant=K_DRAG, inertia_constant=P.fin_inertia_constant):
    """Mean of (f_hx, f_hy) of the right fin over one period of eq. (21), by quadrature."""
    g0, ga, tp, zeta = beat
    t1 = tp / (zeta + 1.0)

    def force(t, k):
        g, gd, gdd = (float(x[0]) for x in fin_angle_eq21(np.array([t]), *beat))
        return fin_force_right(g, gd, gdd, drag_constant, inertia_constant)[k]

    out = []
    for k in range(2):
        total = 0.0
        for a, b in ((0.0, t1), (t1, tp)):  # g'' jumps at the stroke boundaries
            total += quad(force, a, b, args=(k,), epsabs=1e-14, epsrel=1e-11, limit=200)[0]
        out.append(total / tp)
    return np.array(out)


def closed_form(beat):
    """Exact averages of the right fin (notes): k pi^2 (zeta^2-1)/(zeta T^2) gA J1(gA) (sin g0, cos g0)."""
    g0, ga, tp, zeta = beat
    base = K_DRAG * math.pi**2 * (zeta**2 - 1.0) / (zeta * tp**2) * ga * j1(ga)
    return np.array([base * math.sin(g0), base * math.cos(g0)])


def rad(beat_deg):
    return FinBeat.from_degrees(*beat_deg)


# --------------------------------------------------------------------------- Bessel J1


def test_bessel_j1_matches_scipy_on_0_pi():
    x = np.linspace(0.0, math.pi, 401)
    got = np.array([bessel_j1(float(v)) for v in x])
    np.testing.assert_allclose(got, j1(x), rtol=1e-13, atol=1e-15)


def test_bessel_j1_odd():
    for v in (0.1, 0.7, 2.0, 3.1):
        assert bessel_j1(-v) == pytest.approx(-j1(v), rel=1e-13)


# --------------------------------------------------------------------------- exact averages vs quadrature


@pytest.mark.parametrize("beat_deg", PATTERNS)
def test_exact_average_matches_quadrature_of_full_forcing(beat_deg):
    beat = rad(beat_deg)
    ref = quad_average(tuple(beat.as_array()))
    fx, fy, tau = averaged_forcing(beat, P, "right", EXACT)
    scale = K_DRAG * (beat.amplitude * math.pi * (beat.ratio + 1) / beat.period) ** 2  # peak drag force
    np.testing.assert_allclose([fx, fy], ref, rtol=1e-8, atol=1e-10 * scale)


@pytest.mark.parametrize("beat_deg", PATTERNS)
def test_closed_form_typed_in_matches_quadrature(beat_deg):
    # sanity of the reference formula itself (notes' closed form vs quadrature)
    beat = tuple(rad(beat_deg).as_array())
    np.testing.assert_allclose(closed_form(beat), quad_average(beat), rtol=1e-8, atol=1e-14)


@pytest.mark.parametrize("beat_deg", PATTERNS[:5])
def test_fin_inertia_terms_average_to_zero(beat_deg):
    beat = tuple(rad(beat_deg).as_array())
    mean = quad_average(beat, drag_constant=0.0)
    g0, ga, tp, zeta = beat
    peak = P.fin_inertia_constant * ga * (math.pi * (zeta + 1) / tp * max(1, 1 / zeta)) ** 2
    assert peak > 1e-4  # the inertial force itself is not small ...
    np.testing.assert_allclose(mean, 0.0, atol=1e-9 * peak)  # ... but its cycle mean vanishes


def test_symmetric_beat_gives_no_net_force():
    fx, fy, tau = averaged_forcing(FinBeat.from_degrees(80, 25, 0.9, 1.0))
    assert (fx, fy, tau) == pytest.approx((0, 0, 0), abs=1e-15)


def test_zeta_below_one_reverses_thrust():
    fast_power = averaged_forcing(FinBeat.from_degrees(90, 20, 1.0, 4.0))[0]
    fast_recovery = averaged_forcing(FinBeat.from_degrees(90, 20, 1.0, 0.25))[0]
    assert fast_power > 0 > fast_recovery
    # (zeta^2 - 1)/zeta is odd under zeta -> 1/zeta
    assert fast_recovery == pytest.approx(-fast_power, rel=1e-12)


def test_forcing_scales_as_inverse_period_squared():
    a = averaged_forcing(FinBeat.from_degrees(100, 15, 1.0, 3.0))
    b = averaged_forcing(FinBeat.from_degrees(100, 15, 0.5, 3.0))
    np.testing.assert_allclose(b, 4.0 * np.array(a), rtol=1e-12)


@pytest.mark.parametrize("beat_deg", PATTERNS[:4])
def test_moment_is_offset_times_surge_force_right_fin(beat_deg):
    fx, fy, tau = averaged_forcing(rad(beat_deg), P, "right")
    # right pivot at r = (0, -C_p): tau_z = r_x f_y - r_y f_x = +C_p f_x; thrust on the right turns left
    assert tau == pytest.approx(0.03 * fx, rel=1e-14, abs=1e-300)


@pytest.mark.parametrize("beat_deg", PATTERNS[:4])
def test_left_fin_is_mirror_image(beat_deg):
    right = np.array(averaged_forcing(rad(beat_deg), P, "right"))
    left = np.array(averaged_forcing(rad(beat_deg), P, "left"))
    np.testing.assert_allclose(left, right * np.array([1.0, -1.0, -1.0]), rtol=1e-15, atol=0)


def test_averaged_fin_forcing_direct_kernel_call():
    beat = rad((100, 12, 0.8, 5.0))
    coef = coefficient_vector(P)
    out = averaged_fin_forcing(beat.bias, beat.amplitude, beat.period, beat.ratio, -1.0, coef, EXACT,
                               UNIT_K)
    cf = closed_form(tuple(beat.as_array()))
    np.testing.assert_allclose(out, [cf[0], -cf[1], -0.03 * cf[0]], rtol=1e-12)


def test_averaged_forcing_uses_params():
    q = P.replace(fin_force_coef=2.0 * P.fin_force_coef, fin_offset=0.05)
    a = np.array(averaged_forcing(rad((90, 20, 1.0, 4.0)), P))
    b = np.array(averaged_forcing(rad((90, 20, 1.0, 4.0)), q))
    np.testing.assert_allclose(b[:2], 2.0 * a[:2], rtol=1e-12)
    assert b[2] == pytest.approx(0.05 * b[0], rel=1e-12)


def test_averaged_forcing_bad_side():
    with pytest.raises(ValueError, match="side"):
        averaged_forcing(rad((90, 20, 1.0, 4.0)), side="middle")


def test_scaling_multiplies_each_component():
    s = ScalingFunctions.from_dict({
        "format": FORMAT, "features": list(FEATURES),
        "functions": {"K_fx": [{"coef": 0.5, "powers": [0, 0, 0, 0, 0, 0]}],
                      "K_fy": [{"coef": 2.0, "powers": [1, 0, 0, 0, 0, 0]}],
                      "K_m": [{"coef": 0.3, "powers": [0, 0, 0, 1, 0, 0]}, {"coef": 0.1, "powers": [0, 0, 0, 0, 1, 0]},
                              {"coef": 0.2, "powers": [0, 0, 0, 0, 0, 2]}]},
    })
    beat = rad((100, 12, 0.8, 5.0))
    unit = np.array(averaged_forcing(beat, P, "left"))
    scaled = np.array(averaged_forcing(beat, P, "left", scaling=s))
    k = np.array([0.5, 2.0 * beat.bias, 0.3 * 5.0 + 0.1 / 0.8 + 0.2 / 25.0])
    np.testing.assert_allclose(scaled, k * unit, rtol=1e-12)


# --------------------------------------------------------------------------- Taylor forms (26)-(28)


def paper_eq26(g0, ga, tp, zeta, p=P, lp=1.0):
    return (p.fin_chord * p.fin_force_coef * lp**3 * p.fin_span**3 * math.pi**2 * p.water_density * g0 * ga**2
            * (-4 * g0**2 - 3 * (-8 + ga**2)) * (-1 + zeta**2) / (288 * zeta * tp**2))


def paper_eq27_without_mp(g0, ga, tp, zeta, p=P, lp=1.0):
    d, lam, rho = p.fin_chord, p.fin_force_coef, p.water_density
    inner = 4 * d * g0**2 * lam * lp**2 * rho * (-1 + zeta**2) + d * (-8 + ga**2) * lam * lp**2 * rho * (-1 + zeta**2)
    return -(ga**2) * lp * math.pi**2 / (96 * tp**2 * zeta) * inner * p.fin_span**3


@pytest.mark.parametrize("beat_deg", PATTERNS[:6])
def test_taylor_mode_equals_paper_eqs_26_to_28(beat_deg):
    beat = rad(beat_deg)
    args = tuple(beat.as_array())
    fx, fy, tau = averaged_forcing(beat, P, "right", TAYLOR)
    assert fx == pytest.approx(paper_eq26(*args), rel=1e-12)
    assert fy == pytest.approx(paper_eq27_without_mp(*args), rel=1e-12, abs=1e-18)
    assert tau == pytest.approx(P.fin_offset * paper_eq26(*args), rel=1e-12)  # eq. (28)
    fxl, fyl, taul = averaged_forcing(beat, P, "left", TAYLOR)
    assert (fxl, fyl, taul) == pytest.approx((fx, -fy, -tau), rel=1e-15)


def test_taylor_remainder_is_fourth_order_in_angles():
    # x J1(x) = x^2/2 (1 - x^2/8 + x^4/192 - ...), sin b = b (1 - b^2/6 + b^4/120), cos b = 1 - b^2/2 + b^4/24.
    # Exact minus second-order Taylor, relative to the leading term:
    #   f_x: a^4/192 + a^2 b^2/48 + b^4/120,   f_y: a^4/192 + a^2 b^2/16 + b^4/24.
    for eps in (0.04, 0.02, 0.01):
        a, b = eps, 1.5 * eps
        beat = FinBeat(b, a, 1.0, 4.0)
        ex = np.array(averaged_forcing(beat, P, "right", EXACT))
        ta = np.array(averaged_forcing(beat, P, "right", TAYLOR))
        lead = K_DRAG * math.pi**2 * (16 - 1) / 4.0 * a**2 / 2
        rel_x = (ex[0] - ta[0]) / (lead * b)
        rel_y = (ex[1] - ta[1]) / lead
        assert rel_x == pytest.approx(a**4 / 192 + a**2 * b**2 / 48 + b**4 / 120, rel=2e-2)
        assert rel_y == pytest.approx(a**4 / 192 + a**2 * b**2 / 16 + b**4 / 24, rel=2e-2)


def test_taylor_relative_error_ratio_when_halving_angles():
    errs = []
    for eps in (0.08, 0.04, 0.02):
        beat = FinBeat(eps, 0.8 * eps, 1.0, 3.0)
        ex = np.array(averaged_forcing(beat, P, "right", EXACT))
        ta = np.array(averaged_forcing(beat, P, "right", TAYLOR))
        errs.append(np.abs(ex[:2] - ta[:2]) / np.abs(ex[:2]))
    errs = np.array(errs)
    np.testing.assert_allclose(errs[:-1] / errs[1:], 16.0, rtol=0.02)  # halving eps divides the error by 2^4


def test_taylor_cosine_expansion_poor_near_90_deg():
    # Notes: the cos(g0) expansion is poor near 90 deg -- the Taylor f_y has the wrong sign there.
    beat = FinBeat.from_degrees(90, 20, 1.0, 4.0)
    ex = averaged_forcing(beat, P, "right", EXACT)
    ta = averaged_forcing(beat, P, "right", TAYLOR)
    assert ex[1] == pytest.approx(0.0, abs=1e-15)
    assert ta[1] < -0.1 * ex[0]
