"""pectoral_gym.model.tank, the one home of the tank's rules, against the robot's geofence and the env's wall contact.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from pectoral_gym.agents.controllers.stop_band import StopBand, band_violation
from pectoral_gym.hardware.safety.geofence import Geofence
from pectoral_gym.model import tank
from pectoral_gym.model.params import FishParams, body_coefficients


def test_outline_clearance_and_coasting_by_hand():
    # The robot's geofence (pectoral_gym.hardware.safety.geofence.Geofence) is built on these; here they are checked by
    # hand.
    params = FishParams()
    coef = body_coefficients(params)
    outline = tank.Outline.from_params(params)
    half, cp, sp = 0.5 * params.body_length, params.fin_offset, params.fin_span
    assert tuple(outline) == (half, cp, sp)
    assert tank.coast_rate(coef) == pytest.approx(coef.c1 / max(coef.m1, coef.m2), rel=1e-15)
    # Heading +Y at (1.0, 0.5): nose at (1.0, 0.5 + L/2), tail below, right fin pivot at +X (the body's -Y side).
    centres, radii = tank.outline_arrays(1.0, 0.5, math.pi / 2, outline)
    np.testing.assert_allclose(centres, [[1.0, 0.5 + half], [1.0, 0.5 - half], [1.0 + cp, 0.5], [1.0 - cp, 0.5]],
                               atol=1e-15)
    np.testing.assert_array_equal(radii, [cp, cp, sp, sp])
    np.testing.assert_allclose(tank.clearance(1.0, 0.5, math.pi / 2, outline),
                               [1.0 - cp - sp, tank.TANK_LENGTH - 1.0 - cp - sp, 0.5 - half - cp,
                                tank.TANK_WIDTH - 0.5 - half - cp], atol=1e-15)
    k = tank.coast_rate(coef)
    # m dv/dt = -c1 v^2 from v0: v dv/dx = -k v^2, v(x) = v0 exp(-k x), down to v_c after ln(v0 / v_c) / k; at or
    # below v_c, and away from the wall, no distance.
    assert tank.coast_distance(0.2, k, 0.03) == pytest.approx(math.log(0.2 / 0.03) / k, rel=1e-14)
    assert 0.2 * math.exp(-k * tank.coast_distance(0.2, k, 0.03)) == pytest.approx(0.03, rel=1e-14)
    assert tank.coast_distance(0.02, k, 0.03) == 0.0
    assert tank.coast_distance(-0.1, k, 0.03) == 0.0


def test_the_stop_band_is_zero_exactly_where_the_geofence_lets_the_fish_swim_on():
    params = FishParams()
    rule = tank.StopRule(margin=0.05, reaction_time=0.15, contact_speed=0.03)
    fence = Geofence(params, rule)
    band = StopBand.from_params(params, rule)
    rng = np.random.default_rng(1)
    for _ in range(300):
        x, y, psi = rng.uniform(0, tank.TANK_LENGTH), rng.uniform(0, tank.TANK_WIDTH), rng.uniform(-math.pi, math.pi)
        vx, vy = rng.uniform(-0.2, 0.2, 2)
        c, s = math.cos(psi), math.sin(psi)
        breached = fence.breached(x, y, psi, c * vx - s * vy, s * vx + c * vy)
        violation = band_violation(x, y, psi, vx, vy, band, np)
        assert (violation > 0) == breached


def test_numpy_and_casadi_give_the_same_band_and_wall_terms():
    params = FishParams()
    band = StopBand.from_params(params, tank.StopRule(0.05, 0.15, 0.03))
    sym = ca.SX.sym("s", 5)
    band_f = ca.Function("band", [sym], [band_violation(sym[0], sym[1], sym[2], sym[3], sym[4], band, ca)])
    wall_f = ca.Function("wall", [sym], [tank.wall_shortfall(sym[0], sym[1], ca.cos(sym[2]), ca.sin(sym[2]),
                                                             0.1, 0.08, ca, weight=3.0)])
    rng = np.random.default_rng(2)
    for _ in range(50):
        v = np.array([rng.uniform(0, tank.TANK_LENGTH), rng.uniform(0, tank.TANK_WIDTH), rng.uniform(-3, 3),
                      *rng.uniform(-0.3, 0.3, 2)])
        assert float(band_f(v)) == pytest.approx(band_violation(*v, band, np), rel=1e-12, abs=1e-18)
        assert float(wall_f(v)) == pytest.approx(
            tank.wall_shortfall(v[0], v[1], math.cos(v[2]), math.sin(v[2]), 0.1, 0.08, weight=3.0), rel=1e-12)


@pytest.mark.parametrize("psi", [0.0, 0.7, math.pi / 2, 2.5, -1.2])
def test_nose_tail_contact_is_the_point_test_of_nose_and_tail(psi):
    half = 0.1
    c, s = math.cos(psi), math.sin(psi)
    for x in np.linspace(-0.1, tank.TANK_LENGTH + 0.1, 13):
        for y in np.linspace(-0.1, tank.TANK_WIDTH + 0.1, 9):
            points = [(x + h * c, y + h * s) for h in (half, -half)]
            outside = any(not (0 <= px <= tank.TANK_LENGTH and 0 <= py <= tank.TANK_WIDTH) for px, py in points)
            assert tank.nose_tail_contact(x, y, c, s, half) == outside
            gaps = tank.wall_shortfall(x, y, c, s, half, 0.0)
            assert (gaps > 0) == outside


def test_distance_ahead_is_the_ray_to_the_first_wall():
    # By hand: from (1.0, 0.5) along +X the wall X = 2.30 is 1.30 m away; along -Y the wall Y = 0 is 0.5 m;
    # at 45 deg towards +X+Y, Y = 1.15 is reached after 0.65 / sin(45 deg) = 0.919 m, before X = 2.30 (1.838 m).
    assert tank.distance_ahead(1.0, 0.5, 1.0, 0.0) == pytest.approx(1.30)
    assert tank.distance_ahead(1.0, 0.5, 0.0, -1.0) == pytest.approx(0.5)
    r = math.sqrt(0.5)
    assert tank.distance_ahead(1.0, 0.5, r, r) == pytest.approx(0.65 / r)
    assert tank.distance_ahead(1.0, 0.5, 0.0, 0.0) == math.inf


def test_the_stop_rule_checks_itself_once_for_every_holder():
    """A rule outside its bounds is refused by the rule, whoever holds it (env, supervisor, planner, shield)."""
    import dataclasses

    from pectoral_gym.agents.nmpc.settings import NMPCSettings
    from pectoral_gym.envs.core import EnvConfig
    from pectoral_gym.hardware.safety.rules import SafetyConfig

    rule = tank.StopRule(0.05, 0.15, 0.03)
    assert rule == tank.ROBOT_STOP_RULE and rule.as_tuple() == (0.05, 0.15, 0.03)
    assert tank.StopRule.coerce([0.05, 0.15, 0.03]) == rule
    assert tank.StopRule.coerce({"margin": 0.05, "reaction_time": 0.15, "contact_speed": 0.03}) == rule
    assert tank.StopRule(0, 0, 1).margin == 0.0 and isinstance(tank.StopRule(0, 0, 1).margin, float)
    bad = [((-0.01, 0.15, 0.03), "margin"), ((math.nan, 0.15, 0.03), "margin"), ((0.05, -0.1, 0.03), "reaction_time"),
           ((0.05, math.inf, 0.03), "reaction_time"), ((0.05, 0.15, 0.0), "contact_speed"),
           ((0.05, 0.15, -0.03), "contact_speed"), ((True, 0.15, 0.03), "margin"), (("0.05", 0.15, 0.03), "margin")]
    for values, name in bad:
        with pytest.raises(ValueError, match=f"StopRule.{name} must be a finite number"):
            tank.StopRule(*values)
        with pytest.raises(ValueError, match=f"stop_rule: StopRule.{name}"):
            EnvConfig(stop_rule=values)
        with pytest.raises(ValueError, match=f"stop_band: StopRule.{name}"):
            NMPCSettings(stop_band=values)
    with pytest.raises(ValueError, match="StopRule.margin"):
        dataclasses.replace(rule, margin=-1.0)  # a changed field is checked again
    with pytest.raises(dataclasses.FrozenInstanceError):
        rule.margin = 1.0  # type: ignore[misc]
    for shape in ((0.05, 0.15), "abc", 3.0, {"margin": 0.05}):
        with pytest.raises(ValueError, match="stop rule"):
            tank.StopRule.coerce(shape)
    with pytest.raises(ValueError, match="SafetyConfig.stop_rule"):
        SafetyConfig(stop_rule=(0.05, 0.15, 0.03))  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="StopRule"):
        Geofence(FishParams(), (0.05, 0.15, 0.03))  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="StopRule"):
        StopBand.from_params(FishParams(), (0.05, 0.15, 0.03))  # type: ignore[arg-type]
