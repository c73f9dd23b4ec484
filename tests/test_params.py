"""FishParams and FinBeat: Table 1 defaults, derived eq. (20) coefficients, validation.

Reference numbers are typed in from Table 1 of the paper (with the S_A erratum:
0.0325 m^2, not 0.325 m^2) and the derived coefficients are computed here by
hand from those table numbers, not taken from the code.
"""

import dataclasses
import math

import numpy as np
import pytest

from pectoral_gym.model.params import COEF_NAMES, FinBeat, FishParams, coefficient_vector

# Table 1 (paper), SI units. Added masses are listed as -m_ax etc., so m_ax < 0.
TABLE1 = {
    "body_mass": 0.795,
    "body_inertia": 4.26e-4,
    "added_mass_x": -0.095,
    "added_mass_y": -0.1794,
    "added_inertia": -2.7e-5,
    "wetted_area": 0.0325,  # erratum 1: Table 1 prints 0.325
    "drag_coef": 0.3870,
    "lift_coef": 0.0808,
    "moment_coef": 8.5e-3,
    "fin_offset": 0.03,
    "fin_span": 0.061,
    "fin_chord": 0.041,
    "fin_mass": 0.008,
    "fin_effective_mass": 0.008,
    "water_density": 1000.0,
    "fin_force_coef": 4.1464,
    "body_length": 0.198,
    "body_height": 0.1,
}


# --------------------------------------------------------------------------- FishParams


@pytest.mark.parametrize("name,value", sorted(TABLE1.items()))
def test_default_equals_table1(name, value):
    assert getattr(FishParams(), name) == pytest.approx(value, rel=1e-12)


def test_wetted_area_uses_erratum_not_printed_table_value():
    assert FishParams().wetted_area == pytest.approx(0.0325)
    assert FishParams().wetted_area != pytest.approx(0.325)


def test_derived_masses_and_inertia():
    p = FishParams()
    assert p.m1 == pytest.approx(0.795 + 0.095, rel=1e-12)  # = 0.89 kg
    assert p.m1 == pytest.approx(0.89, rel=1e-12)
    assert p.m2 == pytest.approx(0.9744, rel=1e-12)  # 0.795 + 0.1794
    assert p.J3 == pytest.approx(4.53e-4, rel=1e-12)  # 4.26e-4 + 0.27e-4


def test_derived_drag_constants_by_hand():
    p = FishParams()
    c1 = 0.5 * 1000.0 * 0.0325 * 0.3870  # rho S_A C_D / 2 = 6.28875 kg/m
    c2 = 0.5 * 1000.0 * 0.0325 * 0.0808  # rho S_A C_L / 2 = 1.313 kg/m
    c4 = 8.5e-3 / 4.53e-4  # C_M / J3 = 18.764 (1/rad)
    assert c1 == pytest.approx(6.28875)
    assert p.c1 == pytest.approx(c1, rel=1e-12)
    assert p.c2 == pytest.approx(c2, rel=1e-12)
    assert p.c4 == pytest.approx(c4, rel=1e-12)
    assert p.c4 == pytest.approx(18.7638, rel=1e-4)


def test_fin_constants_by_hand():
    p = FishParams()
    # F_n = -(lambda rho D_p S_p^3 / 6) g'|g'| from integrating eq. (11) over s in [0, S_p]
    assert p.fin_drag_constant == pytest.approx(4.1464 * 1000.0 * 0.041 * 0.061**3 / 6.0, rel=1e-12)
    assert p.fin_inertia_constant == pytest.approx(0.008 * 0.061 / 2.0, rel=1e-12)


def test_coefficient_vector_order_and_values():
    p = FishParams().replace(body_mass=0.9, fin_offset=0.05)
    vec = coefficient_vector(p)
    assert vec.shape == (len(COEF_NAMES),)
    assert vec.dtype == np.float64
    for i, name in enumerate(COEF_NAMES):
        assert vec[i] == getattr(p, name)
    assert vec[COEF_NAMES.index("m1")] == pytest.approx(0.9 + 0.095)
    assert vec[COEF_NAMES.index("fin_offset")] == 0.05


def test_fish_params_is_frozen():
    p = FishParams()
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.body_mass = 1.0  # type: ignore[misc]


def test_replace_returns_new_validated_copy():
    p = FishParams()
    q = p.replace(drag_coef=0.5)
    assert q.drag_coef == 0.5 and p.drag_coef == pytest.approx(0.387)
    assert q.c1 == pytest.approx(0.5 * 1000.0 * 0.0325 * 0.5)
    with pytest.raises(ValueError, match="drag_coef"):
        p.replace(drag_coef=-0.1)


@pytest.mark.parametrize(
    "name", ["body_mass", "body_inertia", "wetted_area", "fin_offset", "fin_span", "fin_chord", "water_density",
             "fin_force_coef", "body_length", "body_height"],
)
def test_nonpositive_field_raises_naming_it(name):
    with pytest.raises(ValueError, match=name):
        FishParams(**{name: -1.0})
    with pytest.raises(ValueError, match=name):
        FishParams(**{name: 0.0})


@pytest.mark.parametrize("name", ["drag_coef", "lift_coef", "moment_coef", "fin_mass", "fin_effective_mass"])
def test_negative_coefficient_raises_naming_it(name):
    with pytest.raises(ValueError, match=name):
        FishParams(**{name: -1e-3})
    FishParams(**{name: 0.0})  # zero is allowed (e.g. no lift, massless fin)


@pytest.mark.parametrize("name", sorted(TABLE1))
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_field_raises_naming_it(name, bad):
    with pytest.raises(ValueError, match=name):
        FishParams(**{name: bad})


def test_non_number_field_raises():
    with pytest.raises(ValueError, match="body_mass"):
        FishParams(body_mass="0.8")  # type: ignore[arg-type]


def test_m1_nonpositive_raises():
    # m1 = m_b - m_ax = 0.795 - 0.8 < 0
    with pytest.raises(ValueError, match="m1"):
        FishParams(added_mass_x=0.8)
    with pytest.raises(ValueError, match="m1"):
        FishParams(added_mass_x=0.795)  # m1 == 0


def test_m2_and_j3_nonpositive_raise():
    with pytest.raises(ValueError, match="m2"):
        FishParams(added_mass_y=1.0)
    with pytest.raises(ValueError, match="J3"):
        FishParams(added_inertia=1e-3)


def test_positive_added_mass_allowed_if_effective_mass_positive():
    p = FishParams(added_mass_x=0.1)
    assert p.m1 == pytest.approx(0.695)


# --------------------------------------------------------------------------- FinBeat

OK = {"bias": math.radians(90), "amplitude": math.radians(20), "period": 1.0, "ratio": 4.0}


def _beat(**changes):
    return FinBeat(**{**OK, **changes})


def test_finbeat_valid():
    b = _beat()
    assert b.as_array().tolist() == [OK["bias"], OK["amplitude"], 1.0, 4.0]


def test_finbeat_negative_amplitude():
    with pytest.raises(ValueError, match="amplitude"):
        _beat(amplitude=-0.01)


def test_finbeat_zero_amplitude_allowed():
    assert _beat(amplitude=0.0).amplitude == 0.0


@pytest.mark.parametrize("value", [0.0, -1.0])
def test_finbeat_nonpositive_period(value):
    with pytest.raises(ValueError, match="period"):
        _beat(period=value)


@pytest.mark.parametrize("value", [0.0, -2.0])
def test_finbeat_nonpositive_ratio(value):
    with pytest.raises(ValueError, match="ratio"):
        _beat(ratio=value)


@pytest.mark.parametrize("name", ["bias", "amplitude", "period", "ratio"])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_finbeat_non_finite(name, bad):
    with pytest.raises(ValueError, match=name):
        _beat(**{name: bad})


@pytest.mark.parametrize("name", ["bias", "amplitude", "period", "ratio"])
def test_finbeat_non_number(name):
    with pytest.raises(ValueError, match=name):
        _beat(**{name: "x"})


@pytest.mark.parametrize("bias_deg,amp_deg", [(10, 20), (170, 20), (0, 1), (180, 1), (90, 91)])
def test_finbeat_stroke_leaving_zero_pi(bias_deg, amp_deg):
    with pytest.raises(ValueError, match="bias"):
        FinBeat.from_degrees(bias_deg, amp_deg, 1.0, 4.0)


@pytest.mark.parametrize("bias_deg,amp_deg", [(20, 20), (160, 20), (90, 90), (0, 0), (180, 0)])
def test_finbeat_stroke_touching_limits_allowed(bias_deg, amp_deg):
    b = FinBeat.from_degrees(bias_deg, amp_deg, 1.0, 4.0)
    assert b.bias - b.amplitude >= -1e-15 and b.bias + b.amplitude <= math.pi + 1e-15


def test_finbeat_from_degrees_round_trip():
    b = FinBeat.from_degrees(95.0, 12.0, 0.8, 5.0)
    assert b.bias == pytest.approx(95.0 * math.pi / 180.0, rel=1e-15)
    assert b.amplitude == pytest.approx(12.0 * math.pi / 180.0, rel=1e-15)
    assert b.period == 0.8 and b.ratio == 5.0
    assert b.degrees() == pytest.approx((95.0, 12.0, 0.8, 5.0), rel=1e-14)
    again = FinBeat.from_degrees(*b.degrees())
    np.testing.assert_allclose(again.as_array(), b.as_array(), rtol=1e-14)


def test_finbeat_rest_has_no_motion():
    r = FinBeat.rest()
    assert r.amplitude == 0.0 and r.bias == pytest.approx(math.pi / 2)


def test_finbeat_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        _beat().bias = 0.0  # type: ignore[misc]
