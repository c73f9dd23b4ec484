"""The scaling functions K of the averaged model (``pectoral_gym.model.kfunctions.ScalingFunctions``): polynomial
and spline K evaluated in Python and in the compiled kernel against values computed here (a known polynomial,
``scipy.interpolate`` splines), the ``base`` sway term, file round trips, and malformed files named in one line.

The averaged forcing they scale: ``tests/test_averaging.py``.
"""

import json
import math

import numpy as np
import pytest
from scipy.special import j1

from pectoral_gym.model.averaging import EXACT, TAYLOR, averaged_forcing
from pectoral_gym.model.kfunctions import FEATURES, FORMAT, K_NAMES, ScalingFunctions, default_scaling_path
from pectoral_gym.model.params import FinBeat, FishParams

P = FishParams()


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
    beat = FinBeat.from_degrees(100, 15, 0.8, 4.0)
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
    beat = FinBeat.from_degrees(90, 20, 1.0, 3.0)
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
    beat = FinBeat.from_degrees(70, 25, 1.0, 3.0)
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
