"""Cycle-averaged fin forcing (eqs. 25-28), the Bessel closed form, and the scaling functions K.

References:

* numerical quadrature (scipy ``quad``) over one period of the full forcing,
  eq. (21) fed into the blade-element force (itself checked in ``test_forces``);
* ``scipy.special.j1`` for the Bessel function;
* the paper's eqs. (26)-(28) typed in here (with ``l_p = 1`` and the ``S_p^3``
  that the extraction lost in (27)-(28), without the ``m_p`` terms of (27));
* hand-derived fourth-order Taylor remainders of the closed form.
"""

import json
import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import j1

from pectoral_gym.model.averaging import EXACT, TAYLOR, averaged_fin_forcing, averaged_forcing, bessel_j1
from pectoral_gym.model.dynamics import fin_angle_eq21, fin_force_right
from pectoral_gym.model.kfunctions import FEATURES, FORMAT, K_NAMES, ScalingFunctions, default_scaling_path
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


# --------------------------------------------------------------------------- ScalingFunctions (K)


def _poly_dict():
    # Written in the five-feature layout of files made before inv_ratio: must still load.
    return {
        "format": FORMAT,
        "features": list(FEATURES[:5]),
        "functions": {
            "K_fx": [{"coef": 2.0, "powers": [0, 0, 0, 0, 0]}, {"coef": 3.0, "powers": [1, 2, 0, 0, 0]}],
            "K_fy": [{"coef": -1.5, "powers": [0, 0, 0, 1, 1]}],
            "K_m": [{"coef": 0.25, "powers": [0, 0, 3, 0, 0]}, {"coef": 1.0, "powers": [0, 0, 0, 0, 0]},
                    {"coef": -0.5, "powers": [2, 0, 0, 0, 0]}],
        },
        "metadata": {"source": "test", "grid": [1, 2, 3]},
    }


def test_scaling_evaluate_known_polynomial():
    s = ScalingFunctions.from_dict(_poly_dict())
    b, a, t, z = 1.3, 0.2, 0.8, 4.0
    kfx, kfy, km = s.evaluate(b, a, t, z)
    assert kfx == pytest.approx(2.0 + 3.0 * 1.3 * 0.2**2, rel=1e-14)
    assert kfy == pytest.approx(-1.5 * 4.0 / 0.8, rel=1e-14)
    assert km == pytest.approx(0.25 * 0.8**3 + 1.0 - 0.5 * 1.3**2, rel=1e-14)


def test_scaling_kernel_matches_evaluate():
    s = ScalingFunctions.from_dict(_poly_dict())
    beat = rad((100, 15, 0.8, 4.0))
    k = np.array(s.evaluate(*beat.as_array()))
    unit = np.array(averaged_forcing(beat, P, "right"))
    np.testing.assert_allclose(averaged_forcing(beat, P, "right", scaling=s), k * unit, rtol=1e-12)


def test_kernel_tables_name_the_tables_and_the_sway_convention():
    s = _spline_scaling(sway="base")
    tables = s.kernel_arrays()
    assert tables.base_sway is True and ScalingFunctions.unit().kernel_arrays().base_sway is False
    np.testing.assert_array_equal(tables.table, s.table)
    np.testing.assert_array_equal(tables.powers, s.powers)
    assert tables.osc_table.shape == (2, 0, 0, 0)  # no yaw-oscillation splines
    for axis in range(3):  # padded with the last knot
        n = len(s.knots[axis])
        np.testing.assert_array_equal(tables.knots[axis, :n], s.knots[axis])
        assert np.all(tables.knots[axis, n:] == s.knots[axis][-1])


def test_scaling_json_round_trip(tmp_path):
    s = ScalingFunctions.from_dict(_poly_dict())
    path = tmp_path / "k.json"
    s.save(path)
    back = ScalingFunctions.load(path)
    np.testing.assert_array_equal(back.powers, s.powers)
    np.testing.assert_array_equal(back.coefs, s.coefs)
    assert back.metadata == s.metadata
    assert json.loads(path.read_text())["format"] == FORMAT
    for x in ((1.0, 0.3, 1.0, 4.0), (2.0, 0.1, 0.5, 2.0)):
        assert back.evaluate(*x) == s.evaluate(*x)


def test_scaling_round_trip_of_unit(tmp_path):
    path = tmp_path / "unit.json"
    ScalingFunctions.unit().save(path)
    back = ScalingFunctions.load(path)
    assert back.is_unit
    assert back.evaluate(1.0, 0.3, 0.7, 3.0) == (1.0, 1.0, 1.0)


def test_is_unit_false_for_nontrivial():
    assert not ScalingFunctions.from_dict(_poly_dict()).is_unit


def test_shipped_default_is_identified_and_brings_the_turn_rate_to_the_full_model():
    from pectoral_gym.model.steady import steady_state

    assert default_scaling_path().is_file()
    s = ScalingFunctions.load()
    assert not s.is_unit and s.metadata.get("status") == "identified"
    assert s.metadata["grid"]["name"] == "env"
    # Off the grid (bias 80 deg, amplitude 22 deg are not grid values): the full model is the reference.
    beat = FinBeat.from_degrees(80, 22, 1.0, 4)
    full = steady_state("full", right=beat)
    scaled = steady_state("averaged", right=beat)
    unit = steady_state("averaged", right=beat, scaling="none")
    assert abs(unit.omega / full.omega - 1) > 0.5  # plain averaging turns about twice as fast
    assert scaled.omega == pytest.approx(full.omega, rel=0.1)
    assert scaled.speed == pytest.approx(full.speed, rel=0.05)


def _bad(mutate):
    d = _poly_dict()
    mutate(d)
    return d


MALFORMED = [
    (lambda d: d.update(format="pectoral-gym-scaling/0"), "format"),
    (lambda d: d.pop("format"), "format"),
    (lambda d: d.update(features=["bias", "amplitude", "period", "ratio"]), "features"),
    (lambda d: d["functions"].pop("K_m"), "functions"),
    (lambda d: d["functions"].update(K_extra=[]), "functions"),
    (lambda d: d.update(functions=[1, 2, 3]), "functions"),
    (lambda d: d["functions"]["K_fx"][0].pop("coef"), "K_fx term 0"),
    (lambda d: d["functions"]["K_fy"][0].pop("powers"), "K_fy term 0"),
    (lambda d: d["functions"]["K_m"][1].update(powers=[0, 0, 0, 0]), "K_m term 1"),
    (lambda d: d["functions"]["K_m"][2].update(powers=[0, -1, 0, 0, 0]), "non-negative integers"),
    (lambda d: d["functions"]["K_fx"][1].update(powers=[0.5, 0, 0, 0, 0]), "non-negative integers"),
    (lambda d: d["functions"]["K_fx"][0].update(coef="abc"), "K_fx term 0"),
    (lambda d: d["functions"]["K_fx"][0].update(coef=float("nan")), "finite"),
]


@pytest.mark.parametrize("mutate,message", MALFORMED)
def test_scaling_malformed_dict_raises(mutate, message):
    with pytest.raises(ValueError, match=message):
        ScalingFunctions.from_dict(_bad(mutate))


@pytest.mark.parametrize("mutate,message", MALFORMED[:4])
def test_scaling_malformed_file_names_file(tmp_path, mutate, message):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(_bad(mutate)))
    with pytest.raises(ValueError, match=message) as err:
        ScalingFunctions.load(path)
    assert "bad.json" in str(err.value)


def test_scaling_invalid_json(tmp_path):
    path = tmp_path / "broken.json"
    path.write_text('{"format": "pectoral-gym-scaling/1", ')
    with pytest.raises(ValueError, match="not valid JSON"):
        ScalingFunctions.load(path)


def test_scaling_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.json"):
        ScalingFunctions.load(tmp_path / "nope.json")


def test_k_names_and_features_order():
    assert K_NAMES == ("K_fx", "K_fy", "K_m")
    assert FEATURES == ("bias", "amplitude", "period", "ratio", "inv_period", "inv_ratio")


# --------------------------------------------------------------------------- spline K and the "base" sway term


def _spline_scaling(seed=0, sway="base", polynomial=0.0):
    from scipy.interpolate import make_interp_spline

    rng = np.random.default_rng(seed)
    nodes = (np.radians([45, 60, 75, 95, 110, 135]), np.radians([2.5, 10, 17, 24, 30]), 1 / np.array([5, 3, 2, 1.25]))
    knots = tuple(make_interp_spline(n, np.zeros_like(n), k=3).t for n in nodes)
    table = rng.normal(0.5, 0.3, size=(3, 6, 5, 4))
    coefs = np.full((3, 1), polynomial)
    return ScalingFunctions(np.zeros((3, 1, len(FEATURES))), coefs, {"status": "test"}, knots, table, sway)


def _reference_spline(s, bias, amplitude, ratio):
    """scipy's independent tensor-product B-spline evaluation (with the file's clamping)."""
    from scipy.interpolate import NdBSpline

    x = [min(max(v, k[3]), k[-4]) for v, k in zip((bias, amplitude, 1 / ratio), s.knots, strict=True)]
    return np.array([float(NdBSpline(s.knots, s.table[i], 3)(x)) for i in range(3)])


SPLINE_POINTS = [(1.0, 0.2, 0.8, 2.5), (1.5708, 0.45, 1.3, 4.4), (2.2, 0.1, 0.5, 1.3),
                 (0.6, 0.01, 1.0, 7.0), (2.5, 0.6, 2.0, 1.1)]  # the last two clamp on every axis


@pytest.mark.parametrize("point", SPLINE_POINTS)
def test_spline_k_equals_scipy_in_python_and_in_the_compiled_kernel(point):
    s = _spline_scaling(polynomial=0.25)
    expected = _reference_spline(s, point[0], point[1], point[3]) + 0.25  # plus the constant polynomial part
    np.testing.assert_allclose(s.evaluate(*point), expected, rtol=1e-12, atol=1e-14)
    beat = FinBeat(*point) if point[0] - point[1] >= 0 and point[0] + point[1] <= math.pi else None
    if beat is not None:
        unit = np.array(averaged_forcing(beat, P, "right"))
        base = math.hypot(unit[0], unit[1])
        scaled = np.array(averaged_forcing(beat, P, "right", scaling=s))
        np.testing.assert_allclose(scaled, expected * [unit[0], base, unit[2]], rtol=1e-12)


def test_base_sway_term_is_finite_and_nonzero_at_90_deg_bias():
    beat = rad((90, 20, 1.0, 3.0))
    unit = np.array(averaged_forcing(beat, P, "left"))
    assert abs(unit[1]) < 1e-12 * abs(unit[0])  # the plain average has no sway force at 90 deg
    k = np.array([[0.9], [0.3], [0.2]])
    paper = ScalingFunctions(np.zeros((3, 1, len(FEATURES))), k, {})
    base = ScalingFunctions(np.zeros((3, 1, len(FEATURES))), k, {}, sway="base")
    assert averaged_forcing(beat, P, "left", scaling=paper)[1] == pytest.approx(0.0, abs=1e-12 * unit[0])
    # left fin: sway mirrored; the base term is the average force magnitude (= fx at 90 deg)
    assert averaged_forcing(beat, P, "left", scaling=base)[1] == pytest.approx(-0.3 * unit[0], rel=1e-12)
    assert base.paper_k_fy(*beat.as_array()) == math.inf or abs(base.paper_k_fy(*beat.as_array())) > 1e12
    assert not base.is_unit


def test_taylor_mode_base_sway_uses_the_taylor_base():
    # Second-order Taylor form of base = c gA J1(gA): c gA^2 (8 - gA^2) / 16, consistent with eq. (27).
    beat = rad((70, 25, 1.0, 3.0))
    base = ScalingFunctions(np.zeros((3, 1, len(FEATURES))), np.ones((3, 1)), {}, sway="base")
    c = P.fin_drag_constant * math.pi**2 * (3.0**2 - 1) / (3.0 * 1.0**2)
    a = beat.amplitude
    assert averaged_forcing(beat, P, "right", TAYLOR, base)[1] == pytest.approx(c * a * a * (8 - a * a) / 16, rel=1e-12)
    exact = averaged_forcing(beat, P, "right", EXACT, base)[1]
    assert exact == pytest.approx(c * a * j1(a), rel=1e-12)


def test_spline_file_round_trip(tmp_path):
    s = _spline_scaling(seed=2, polynomial=0.1)
    path = tmp_path / "spline.json"
    s.save(path)
    data = json.loads(path.read_text())
    assert data["format"] == FORMAT == "pectoral-gym-scaling/3" and data["sway"] == "base"
    back = ScalingFunctions.load(path)
    assert back.sway == "base" and back.has_spline
    np.testing.assert_array_equal(back.table, s.table)
    for k_back, k in zip(back.knots, s.knots, strict=True):
        np.testing.assert_array_equal(k_back, k)
    for point in SPLINE_POINTS:
        assert back.evaluate(*point) == s.evaluate(*point)


def test_format_1_files_still_load_with_paper_sway():
    d = _poly_dict()
    d["format"] = "pectoral-gym-scaling/1"
    s = ScalingFunctions.from_dict(d)
    assert s.sway == "paper" and not s.has_spline


def _spline_dict():
    d = _spline_scaling().to_dict()
    return json.loads(json.dumps(d))


SPLINE_MALFORMED = [
    (lambda d: d.update(sway="sideways"), "sway"),
    (lambda d: d["spline"].update(degree=2), "degree 3"),
    (lambda d: d["spline"].update(axes=["bias", "amplitude", "ratio"]), "axes"),
    (lambda d: d["spline"].update(extrapolation="linear"), "extrapolation"),
    (lambda d: d["spline"]["coefficients"].pop("K_m"), "malformed spline"),
    (lambda d: d["spline"]["coefficients"].update(K_fx=[1.0, 2.0]), "malformed spline"),
    (lambda d: d["spline"]["knots"][0].reverse(), "non-decreasing"),
    (lambda d: d["spline"]["knots"][1].pop(), "malformed spline"),
    (lambda d: d["spline"]["coefficients"]["K_fy"].__setitem__(3, None), "malformed spline|finite"),
    (lambda d: d.update(spline=[1, 2]), "'spline' must be an object"),
]


@pytest.mark.parametrize("mutate,message", SPLINE_MALFORMED)
def test_spline_malformed_dict_raises(mutate, message):
    d = _spline_dict()
    mutate(d)
    with pytest.raises(ValueError, match=message):
        ScalingFunctions.from_dict(d, "k.json")


def test_spline_constructor_checks():
    s = _spline_scaling()
    with pytest.raises(ValueError, match="both knots and a table"):
        ScalingFunctions(s.powers, s.coefs, {}, s.knots, None)
    with pytest.raises(ValueError, match="at least 4 coefficients"):
        ScalingFunctions(s.powers, s.coefs, {}, (s.knots[0], s.knots[1], s.knots[2][:7]), s.table[..., :3])
    with pytest.raises(ValueError, match="sway"):
        ScalingFunctions(s.powers, s.coefs, {}, sway="cos")
